"""A run to repeat: the counterexample (or least robust run) of ``falsify.json``, or a certification's failing
run (``certify.json``): every input needed to repeat it bit for bit (``ballbeam run --replay``, ``ballbeam view
--replay``).

The file keeps the run as ``{"controller", "controller_sha256", "plant", "ideal_sensors", "x0_m", "theta0_rad",
"seed", "noise", "duration_s", "parameters" (the changes from the defaults by dotted name), "requirements" (name:
formula), "robustness"}`` and, when the run had them, ``flick_time_s``, ``flick_speed_m_s`` and ``setpoint_m``;
a malformed file is refused naming the file and the field.

A replay file is data, not a program: the controller it names runs only when it is a built-in (catalogue) name,
the project's own code, or when the user names the same controller with ``--controller`` or passes
``--trust-replay-controller``; either way what would run is first checked against ``controller_sha256``
(``controller_identity``: the SHA-256 of a ``MODULE:CLASS``'s module file or of an ``avr:``/``fmu:`` image,
read without importing or loading anything).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.app.options import MAX_RUN_S
from twin.image import open_regular
from twin.parameters import MAX_FILE_BYTES, ParameterError, Parameters, load_json
from twin.requirements import ROBUSTNESS_LIMIT, Requirement, Spec, parse_requirements
from twin.rigs.backends import DEFAULT_PLANT, ENGINES, engine_policy, plant_choices

__all__ = [
    "TRUST_OPTION",
    "Replay",
    "controller_identity",
    "load_replay",
    "refuse_given",
    "replay_command",
    "replay_controller",
    "replay_entry",
]

# Where a run to repeat sits in each kind of file, in order of preference.
RUN_KEYS = ("counterexample", "least_robust")
# The runs of the job, after the runs to repeat in the file (falsify's trace, certify's runs): a file larger
# than REPLAY_HEAD_BYTES is read up to the first of them only.
BULK_KEYS = ("trace", "runs")
# What precedes the bulk holds at most a few copies of a requirements file and a parameter file (each at most
# MAX_FILE_BYTES): a search of 100 000 runs writes a trace of ~26 MB after it, never read for a replay.
REPLAY_HEAD_BYTES = 8 * MAX_FILE_BYTES
TRUST_OPTION = "--trust-replay-controller"
_HASH_CHUNK = 1 << 20


@dataclass(frozen=True)
class Replay:
    controller: str
    x0_m: float
    theta0_rad: float
    seed: int
    noise: bool
    duration_s: float
    params: Parameters
    requirements: tuple[Requirement, ...]
    robustness: dict[str, float]  # as the file states it
    source: str
    flick: tuple[float, float] | None = None  # (time after release, s; speed, m/s)
    setpoint_m: float | None = None
    controller_sha256: str | None = None  # None: a built-in name, or a file written before hashes
    plant: str = "twin"  # the engine the run was made on: "twin" (MuJoCo) or "reference" (the fast engine)
    ideal_sensors: bool = False


def _read_head(path: str | Path) -> str:
    """The replay file's text: whole up to ``REPLAY_HEAD_BYTES``, else its head up to the job's bulk (the runs to
    repeat come before it), closed as a JSON object. A file that is not a regular file is refused before it is
    read."""
    fd = open_regular(path, ParameterError, "replay file", "a replay file is falsify.json or certify.json")
    with os.fdopen(fd, "rb") as fh:
        try:
            raw = fh.read(REPLAY_HEAD_BYTES + 1)
        except OSError as exc:
            raise ParameterError(f"{path}: cannot read replay file ({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8-sig") if len(raw) <= REPLAY_HEAD_BYTES else _decode_head(raw)
    except UnicodeDecodeError as exc:
        raise ParameterError(f"{path}: not a JSON file: {exc}") from None
    if len(raw) <= REPLAY_HEAD_BYTES:
        return text
    end = _head_end(text)
    if end is None:
        raise ParameterError(
            f"{path}: larger than {REPLAY_HEAD_BYTES} bytes and no run to repeat before its "
            f"{' or '.join(BULK_KEYS)} within them (falsify --out's or certify --out's file keeps it first)"
        )
    return text[:end] + "}"


def _decode_head(raw: bytes) -> str:
    """The head's text; a UTF-8 character cut by the head's end is dropped."""
    head = raw[:REPLAY_HEAD_BYTES]
    try:
        return head.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 3:  # not a cut character: the file is not UTF-8
            raise
        return head[: exc.start].decode("utf-8-sig")


def _skip(text: str, i: int) -> int:
    """Past the JSON white space at ``i``."""
    while text[i : i + 1] in (" ", "\t", "\n", "\r") and i < len(text):
        i += 1
    return i


def _head_end(text: str) -> int | None:
    """Where the top-level object's members before the first ``BULK_KEYS`` member end (None: not found in
    ``text``): its values are skipped as JSON, not built."""
    decoder = json.JSONDecoder()
    i = _skip(text, 0)
    if text[i : i + 1] != "{":
        return None
    end, i = i + 1, i + 1
    try:
        while True:
            key, i = decoder.raw_decode(text, _skip(text, i))
            if key in BULK_KEYS:
                return end
            i = _skip(text, i)
            if text[i : i + 1] != ":":
                return None
            _, end = decoder.raw_decode(text, _skip(text, i + 1))
            i = _skip(text, end)
            if text[i : i + 1] != ",":
                return None
            i += 1
    except (ValueError, RecursionError):  # cut by the head's end, or not JSON: the caller says so
        return None


def load_replay(path: str | Path) -> Replay:
    """The run a falsify.json or certify.json names (its counterexample, else its least robust run)."""
    text = _read_head(path)
    try:
        data = load_json(text)
    except (ValueError, RecursionError) as exc:
        raise ParameterError(f"{path}: not a JSON file: {exc}") from None
    run = next((data[k] for k in RUN_KEYS if isinstance(data, dict) and data.get(k)), None)
    if not isinstance(run, dict):
        raise ParameterError(
            f"{path}: no run to repeat (expected {' or '.join(RUN_KEYS)}: falsify --out's file)"
        )

    def field(name: str, kind: type | tuple[type, ...], check: Any = None) -> Any:
        value = run.get(name)
        ok = isinstance(value, kind) and not (kind is not bool and isinstance(value, bool))
        if ok and isinstance(value, float):
            ok = math.isfinite(value)
        if not ok or (check is not None and not check(value)):
            raise ParameterError(f"{path}: {name} = {value!r} is not what a run needs")
        return value

    number = (int, float)
    parameters = field("parameters", dict)
    try:
        params = Parameters().with_overrides(parameters, origin=f"{path}: parameters")
    except ParameterError as exc:
        raise ParameterError(str(exc)) from None
    formulas = field("requirements", dict)
    requirements = parse_requirements({"requirements": formulas}, f"{path}: requirements")
    robustness = field("robustness", dict)
    optional = {}
    for name in ("flick_time_s", "flick_speed_m_s", "setpoint_m"):
        if run.get(name) is not None:
            optional[name] = float(field(name, number))
    flick = None
    if "flick_time_s" in optional:
        flick = (optional["flick_time_s"], optional.get("flick_speed_m_s", 0.0))
    sha = None
    if run.get("controller_sha256") is not None:
        sha = field("controller_sha256", str, lambda v: re.fullmatch(r"[0-9a-f]{64}", v) is not None)
    if "plant" in run:
        plant = field("plant", str, lambda v: v in plant_choices())
    else:  # a file written before the engine was kept per run: a fast search's runs are the fast engine's
        settings = data.get("settings")
        engine = settings.get("engine") if isinstance(settings, dict) else None
        plant = engine_policy(engine).decider if engine in ENGINES else DEFAULT_PLANT
    return Replay(
        controller=field("controller", str, lambda v: 0 < len(v) < 4096),
        x0_m=float(field("x0_m", number)),
        theta0_rad=float(field("theta0_rad", number)),
        seed=field("seed", int, lambda v: 0 <= v < 2**63),
        noise=field("noise", bool),
        duration_s=float(field("duration_s", number, lambda v: 0 < v <= MAX_RUN_S)),
        params=params,
        requirements=requirements,
        robustness={str(k): float(v) for k, v in robustness.items() if isinstance(v, (int, float))},
        source=str(path),
        flick=flick,
        setpoint_m=optional.get("setpoint_m"),
        controller_sha256=sha,
        plant=plant,
        ideal_sensors=field("ideal_sensors", bool) if "ideal_sensors" in run else False,
    )


def refuse_given(options: list[tuple[str, Any]]) -> None:
    """Refuse the options (option, value; None: not given) that a replay brings itself."""
    given = [option for option, value in options if value is not None and value is not False]
    if given:
        raise ParameterError(f"--replay brings the run's own {', '.join(given)}: drop them")


def is_code(spec: str) -> bool:
    """Whether ``spec`` names code from outside the project: ``MODULE:CLASS``, ``avr:`` or ``fmu:`` (a name
    without a colon is the catalogue's, the project's own controllers)."""
    return ":" in spec


def replay_command(path: str | Path, controller: str) -> str:
    """The command that repeats a job's run from its file: your own code named on it (the file alone does not
    run it)."""
    named = ["--controller", controller] if is_code(controller) else []
    return shlex.join(["ballbeam", "run", "--replay", str(path), *named])


def controller_file(spec: str) -> Path | None:
    """The file whose bytes ``controller_identity`` hashes: its host's (``twin.app.hosts``: a firmware image or
    an FMU, or the module file of a ``MODULE:CLASS`` as the import would find it, located without running
    anything); None for a catalogue name or a module that cannot be found."""
    from twin.app.hosts import host_of

    return host_of(spec).image(spec)


def controller_identity(spec: str, *, missing_ok: bool = False) -> str | None:
    """The SHA-256 (hex) of what ``spec`` names (``controller_file``): None for a catalogue name; a
    ``ParameterError`` naming the file when it cannot be read or is not a regular file. The module file alone
    is hashed, not what it imports. ``missing_ok``: None for a module its file cannot be found for (a writer's
    job still runs: its file then records no hash, and a replay needs the code named or trusted)."""
    from twin.app.hosts import MODULE, host_of

    path = controller_file(spec)
    if path is None:
        if host_of(spec) is MODULE and not missing_ok:
            raise ParameterError(f"--controller {spec}: module {spec.partition(':')[0]} not found")
        return None
    fd = open_regular(
        path, ParameterError, f"--controller {spec}", "a controller is a module file or an image"
    )
    with os.fdopen(fd, "rb") as fh:
        digest = hashlib.sha256()
        try:
            while chunk := fh.read(_HASH_CHUNK):
                digest.update(chunk)
        except OSError as exc:
            raise ParameterError(f"--controller {spec}: {path}: {exc.strerror or exc}") from None
    return digest.hexdigest()


def replay_controller(replay: Replay, named: str | None, trusted: bool, prog: str) -> None:
    """Refuse to run the replay's controller unless it may run (module doc): a catalogue name, or the same
    controller named with ``--controller`` (``named``), or ``trusted`` (``--trust-replay-controller``: what will
    run is said on stderr); what runs must match the file's ``controller_sha256``."""
    spec, src = replay.controller, replay.source
    if named is not None and named != spec:
        raise ParameterError(
            f"{src}: controller = {spec!r} but --controller {named!r}: a replay repeats the file's controller"
        )
    if not is_code(spec):
        return  # the project's own controllers: nothing of the file's runs but its numbers
    if named is None and not trusted:
        raise ParameterError(
            f"{src}: controller = {spec!r} names code to run (a module, firmware image or FMU): a replay runs "
            f"it only if you name it (--controller {spec}) or pass {TRUST_OPTION}"
        )
    if replay.controller_sha256 is None:
        if not trusted:
            return  # named on the command line: the user's choice, with nothing to check it against
        what = f"{spec} as it is now (no controller_sha256 in the file: written before hashes)"
    elif (current := controller_identity(spec)) != replay.controller_sha256:
        raise ParameterError(
            f"{src}: controller_sha256 = {replay.controller_sha256} but {spec} ({controller_file(spec)}) is "
            f"now {current}: not the controller the file's run was made with"
        )
    else:
        what = f"{spec} ({controller_file(spec)}, sha256 {current}, as the file records)"
    if trusted and named is None:
        print(f"{prog}: {TRUST_OPTION}: running {what} from {src}", file=sys.stderr)


def replay_entry(
    controller: str,
    run: dict[str, Any],
    noise: bool,
    duration_s: float,
    spec: Spec,
    *,
    controller_sha256: str | None,
    plant: str,
    ideal_sensors: bool = False,
) -> dict[str, Any]:
    """A job's run as the file keeps it (``load_replay`` reads it back): ``run`` is its record with the run's
    ``parameters`` (``Parameters.changed``) and each requirement's robustness; ``controller_sha256``:
    ``controller_identity(controller)`` when the job started; ``plant``: the engine that made the run."""
    return {
        "controller": controller,
        "controller_sha256": controller_sha256,
        "plant": plant,
        "ideal_sensors": ideal_sensors,
        "x0_m": run["x0_m"],
        "theta0_rad": run["theta0_rad"],
        "seed": run["seed"],
        "noise": noise,
        "duration_s": duration_s,
        "parameters": run["parameters"],
        "requirements": {r.name: r.formula for r in spec.requirements},
        # a run whose controller failed has no signals: it violates every requirement, stated at the limit
        "robustness": run.get("requirements") or {r.name: -ROBUSTNESS_LIMIT for r in spec.requirements},
        "ball_lost": run["ball_lost"],
    }
