"""The same law in three forms, from the thesis's starts, and each difference explained by its cause, measured.

    python     ``appendix-sf``: the law in Python (double), on the PCI-1712 (12-bit ADC, block means, 12-bit DAC)
    c          the C client ``examples/c/bb_sf`` on the PC (double), served the same runs over the wire
    firmware   ``examples/avr``'s image on a simulated ATmega328P (float, the board's 10-bit ADC averaging its own
               conversions, the SPI DAC, its own timing)

Each cause measured on its own, with the Python law:

    quantization  the board's input grid on the card (``board_input_grid``): the front end maps the ±5 V signals
                  onto the ADC's 0…V_ref, so the card at ``mcu_io.adc_bits`` over the same span, its codes
                  centred where the firmware centres its counts, reads what the board reads
    timing        the firmware's longest update as the output latency (rounded up to a physics step)
    precision     the firmware's own run replayed: the ADC results it read, through the law built for the host
                  in single and in double precision (``host_law``): the DAC words that differ and by how much

and the figures of the firmware form set beside the Python form's and each cause's (``compare``; ``render``
writes the table and the sentences from them: nothing in them is typed in).
"""

from __future__ import annotations

import math
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from controllers import thesis_numbers as T
from twin.app.fanout import Runs, Served, run_starts
from twin.app.sweep import point_seeds
from twin.avr.core import Conversion, Frame
from twin.parameters import Parameters

__all__ = [
    "FIGURES",
    "board_input_grid",
    "compare",
    "host_law",
    "host_words",
    "period_inputs",
    "render",
    "starts",
]

ROOT = Path(__file__).resolve().parents[2]
C_DIR = ROOT / "examples" / "c"
AVR_DIR = ROOT / "examples" / "avr"

# The verdict's figures the table compares, with their unit's scale and name.
FIGURES = (
    ("steady_x_m", 1e3, "mm", "offset"),
    ("limit_cycle_x_pp_m", 1e3, "mm", "ball limit cycle"),
    ("limit_cycle_theta_pp_rad", 1e3, "mrad", "beam limit cycle"),
)

_HOST_LAW = """#include <math.h>
#include <stdint.h>
#include <stdio.h>
PRECISION
#include "appendix_sf.c"
#include "rig_io.h"
/* examples/avr's interrupt without the pins: per period the two channels' count sums in, the DAC word out. */
int main(void) {
    static const sf_calibration cal = RIG_SF_CALIBRATION;
    sf_state s; unsigned ball, angle; int started = 0;
    while (scanf("%u %u", &ball, &angle) == 2) {
        double b = io_signal_v((uint16_t)ball), a = io_signal_v((uint16_t)angle);
        double command = RIG_COMMAND_ZERO_V;
        if (!started) started = sf_start(&s, &cal, b, a) == 0;
        else if (sf_update(&s, b, a, &command) != 0) command = RIG_COMMAND_ZERO_V;
        printf("%u\\n", (unsigned)io_dac_frame(command));
    }
    return 0;
}
"""


def host_law(folder: Path, *, single: bool = True) -> Path:
    """examples/avr's law and I/O arithmetic compiled for the host, in single precision (``-Ddouble=float``: the
    AVR's ``double`` is IEEE binary32) or double: per line the period's count sums in, the DAC word out."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (cc or gcc) to build the law for the host")
    source = folder / "host_law.c"
    source.write_text(_HOST_LAW.replace("PRECISION", "#define double float" if single else ""))
    out = folder / ("host_law_float" if single else "host_law_double")
    flags = ["-fsingle-precision-constant"] if single else []
    done = subprocess.run(
        [cc, "-std=c99", "-O2", "-ffp-contract=off", "-fno-fast-math", *flags, f"-I{C_DIR}", f"-I{AVR_DIR}",
         "-o", str(out), str(source), "-lm"],
        capture_output=True, text=True,
    )  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"building the law for the host failed: {done.stderr.strip()[-400:]}")
    return out


def board_input_grid(params: Parameters) -> dict[str, float]:
    """The card's ADC set to read what the board's does: the signal span the front end maps onto 0…V_ref, at
    the board's bits, with the codes centred half a step up (the firmware reads a count n as its bin's centre,
    n + ½: examples/avr/rig_io.h), so that v_min + round((v − v_min)/step)·step is its reading."""
    io = params.mcu_io
    low = -io.input_offset_v / io.input_gain_v_per_v
    high = (io.adc_reference_v - io.input_offset_v) / io.input_gain_v_per_v
    half = (high - low) / 2**io.adc_bits / 2
    return {"daq.adc_bits": io.adc_bits, "daq.adc_min_v": low + half, "daq.adc_max_v": high + half}


def starts() -> list[tuple[str, float, float]]:
    """The chapter 6 hardware starts and the chapter 4 starts: (name, x0 m, θ0 rad)."""
    named = [(name, x, th) for name, (x, th) in T.HARDWARE_STARTS.items()]
    return named + [(f"chapter 4 ({x:+g}, {th:+g})", x, th) for x, th in T.CHAPTER4_STARTS]


def period_inputs(frames: Sequence[Frame], conversions: Sequence[Conversion]) -> list[list[Conversion]]:
    """The ADC results the firmware read before each frame (after the one before): each update's inputs."""
    out, last = [], 0
    for frame in frames:
        out.append([c for c in conversions if last < c.cycle < frame.cycle])
        last = frame.cycle
    return out


def host_words(law: Path, sums: Sequence[tuple[int, int]]) -> list[int]:
    """The DAC words a ``host_law`` build writes for per-period (ball, angle) count sums."""
    text = "".join(f"{b} {a}\n" for b, a in sums)
    done = subprocess.run([str(law)], input=text, capture_output=True, text=True, check=True)
    return [int(w) for w in done.stdout.split()]


def _replay(elf: Path, params: Parameters, x0_m: float, theta0_rad: float, seed: int, duration_s: float,
            laws: tuple[Path, Path]) -> dict[str, Any]:  # fmt: skip
    """The firmware's run with its ADC results kept, replayed through the host's float and double builds."""
    from twin.avr.firmware import AvrFirmware
    from twin.rigs.sim import run_closed_loop

    fw = AvrFirmware(elf, params, record=True)
    run_closed_loop(fw, x0_m=x0_m, theta0_rad=theta0_rad, duration_s=duration_s, seed=seed, params=params)
    frames = fw.frames[1:]  # the first is main's zero command, before any interrupt
    sums = [
        (sum(c.value for c in inside if c.channel == 0), sum(c.value for c in inside if c.channel == 1))
        for inside in period_inputs(frames, fw.conversions)
    ]
    single, double = (np.array(host_words(law, sums)) for law in laws)
    firmware = np.array([f.word for f in frames])
    codes = np.abs((single & 0x0FFF) - (double & 0x0FFF))
    return {
        "words": len(firmware),
        "float_equal": bool(np.array_equal(firmware, single)),
        "differ": int(np.count_nonzero(codes)),
        "max_codes": int(codes.max(initial=0)),
    }


def _with_c_client(client: Path, sessions: int, work: Callable[[Served], Any]) -> Any:
    """``work(job)`` with the served ``job``'s ``sessions`` sessions answered by the C client (0: every one, the
    client ending when no session follows within its timeout)."""
    from twin.serving.server import Server, SessionSettings

    job = Served(Server(SessionSettings(), log=lambda _: None), next_wait_s=3.0)
    with job.server:
        argv = [
            str(client),
            "udp",
            "127.0.0.1",
            str(job.server.port),
            "--sessions",
            str(sessions),
            "--timeout",
            "5",
        ]
        proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        out = work(job)
        _, err = proc.communicate(timeout=120)
    # 1: a session lost the ball (the region's far starts do): the job's records say so, not the exit code
    if proc.returncode not in (0, 1):
        raise RuntimeError(f"the C client failed (exit {proc.returncode}): {err.strip()[-300:]}")
    return out


def _served_c(runs: Runs, grid: np.ndarray, seeds: np.ndarray, client: Path) -> list[dict[str, Any] | None]:
    """The runs served to the C client, one session each."""
    records, complete = _with_c_client(
        client, len(grid), lambda job: run_starts(runs, grid, seeds, serve=job)
    )
    if not complete:
        raise RuntimeError("the C client's runs did not complete")
    return records


def _validations(elf: Path, c_client: Path | None, p: Parameters, workers: int) -> dict[str, Any]:
    """``validate``'s default battery for each form: passed, and each check's verdict and measurement."""
    from twin.app.validate import ValidationReport, validate

    def summary(report: ValidationReport) -> dict[str, Any]:
        return {
            "passed": report.passed,
            "checks": {c.name: {"passed": c.passed, "measured": c.measured} for c in report.checks},
        }

    python = validate("appendix-sf", p, workers=workers)
    out = {"python": summary(python), "firmware": summary(validate(f"avr:{elf}", p, workers=workers))}
    if c_client is not None:
        report = _with_c_client(c_client, 0, lambda job: validate("appendix-sf", p, serve=job))
        if not report.complete:
            raise RuntimeError("the C client's validation did not complete")
        out["c"] = summary(report)
    return out


def compare(
    elf: Path,
    c_client: Path | None,
    *,
    duration_s: float = 15.0,
    seed: int = 0,
    workers: int = 2,
    params: Parameters | None = None,
    progress: Callable[[str], None] = lambda _: None,
    validation: bool = False,
) -> dict[str, Any]:
    """The three forms and the two single-cause Python runs from ``starts()`` (noise on, one seed per start as a
    job draws them), the precision replay of each firmware run, and the resolutions and delay they stand for."""
    p = params or Parameters()
    named = starts()
    grid = np.array([(x, th) for _, x, th in named], dtype=float)
    seeds = point_seeds(seed, len(grid))
    spec = f"avr:{elf}"

    def job(controller: str, rig: Parameters) -> list[dict[str, Any] | None]:
        records, _ = run_starts(
            Runs(controller, rig, duration_s, True, "twin", False), grid, seeds, workers=workers
        )
        return records

    progress("firmware")
    forms: dict[str, list[dict[str, Any] | None]] = {"firmware": job(spec, p)}
    update_s = max(r["firmware"]["update_cycles_max"] for r in forms["firmware"] if r) / p.mcu_io.clock_hz
    dt = p.physics.timestep_s
    delay_s = round(math.ceil(update_s / dt - 1e-9) * dt, 12)
    progress("python")
    forms["python"] = job("appendix-sf", p)
    if c_client is not None:
        progress("c")
        forms["c"] = _served_c(Runs("appendix-sf", p, duration_s, True, "twin", False), grid, seeds, c_client)
    progress("causes")
    forms["quantization"] = job("appendix-sf", p.with_overrides(board_input_grid(p)))
    forms["timing"] = job("appendix-sf", p.with_overrides({"daq.output_latency_s": delay_s}))
    progress("precision")
    with tempfile.TemporaryDirectory() as tmp:
        laws = (host_law(Path(tmp), single=True), host_law(Path(tmp), single=False))
        precision = [
            _replay(elf, p, x, th, int(s), duration_s, laws)
            for (_, x, th), s in zip(named, seeds, strict=True)
        ]
    span = p.daq.adc_max_v - p.daq.adc_min_v
    if validation:
        progress("validation")
    return {
        **({"validation": _validations(elf, c_client, p, workers)} if validation else {}),
        "settings": {"duration_s": duration_s, "seed": seed, "noise": True, "image": str(elf)},
        "resolution_v": {"python": span / 2**p.daq.adc_bits, "firmware": span / 2**p.mcu_io.adc_bits},
        "dac_step_v": p.mcu_io.dac_reference_v / 2**p.mcu_io.dac_bits,
        "delay_s": delay_s,
        "starts": [
            {
                "name": name,
                "x0_m": x,
                "theta0_rad": th,
                "seed": int(s),
                "forms": {form: records[i] for form, records in forms.items()},
                "precision": precision[i],
            }
            for i, ((name, x, th), s) in enumerate(zip(named, seeds, strict=True))
        ],
    }


def _cell(record: dict[str, Any] | None) -> str:
    if record is None:
        return "not run"
    if record.get("failed"):
        return "failed"
    held = "held" if record["held"] else ("lost" if record["ball_lost"] else "not held")
    figures = [
        f"{record[key] * scale:{'+' if key == 'steady_x_m' else ''}.1f} {unit}"
        for key, scale, unit, _ in FIGURES
    ]
    return f"{held}, " + ", ".join(figures)


def render(result: dict[str, Any]) -> str:
    """The table (one row per start: each form's held, offset, ball and beam limit cycles) and, per figure, the
    firmware's difference from the Python form with the share each single cause gives of it."""
    forms = [
        ("python", "Python (double)"),
        ("c", "C on the PC (double)"),
        ("firmware", "firmware (float)"),
        ("quantization", "Python + the board's 10-bit input"),
        ("timing", "Python + the firmware's delay"),
    ]
    present = [(key, title) for key, title in forms if key in result["starts"][0]["forms"]]
    settings = result["settings"]
    lines = [
        f"Each cell: held or not, then {', '.join(name for *_, name in FIGURES)} (p-p), over "
        f"{settings['duration_s']:g} s runs, noise on, one seed per start (job seed {settings['seed']}).",
        "",
        "| start | "
        + " | ".join(title for _, title in present)
        + " | precision: words differing (max codes) |",
        "|---" * (len(present) + 2) + "|",
    ]
    for s in result["starts"]:
        p = s["precision"]
        lines.append(
            f"| {s['name']} ({s['x0_m']:+g} m, {s['theta0_rad']:+g} rad) | "
            + " | ".join(_cell(s["forms"][key]) for key, _ in present)
            + f" | {p['differ']} of {p['words']} ({p['max_codes']}) |"
        )
    lines += ["", *_causes(result)]
    if "validation" in result:
        lines += ["", *_validation_table(result["validation"])]
    return "\n".join(lines) + "\n"


def _validation_table(validation: dict[str, Any]) -> list[str]:
    """``validate``'s default battery, a column per form, a row per check (the measured value, ✗ where failed)."""
    titles = {"python": "Python (double)", "c": "C on the PC (double)", "firmware": "firmware (float)"}
    forms = [form for form in ("python", "c", "firmware") if form in validation]
    names = list(dict.fromkeys(name for form in forms for name in validation[form]["checks"]))
    lines = [
        "The default validation (`ballbeam validate`):",
        "",
        "| check | " + " | ".join(titles[f] for f in forms) + " |",
        "|---" * (len(forms) + 1) + "|",
        "| **verdict** | " + " | ".join("PASS" if validation[f]["passed"] else "FAIL" for f in forms) + " |",
    ]
    for name in names:
        cells = []
        for form in forms:
            check = validation[form]["checks"].get(name)
            if check is None:
                cells.append("—")
            else:
                mark = {True: "", False: "✗ ", None: "not run: "}[check["passed"]]
                cells.append(mark + check["measured"].removeprefix("not run: "))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def _causes(result: dict[str, Any]) -> list[str]:
    """Per figure, over the starts every form held: the firmware's mean change from Python, each single cause's."""
    kept = [s for s in result["starts"] if all(r and r["held"] for r in s["forms"].values())]
    out = []
    r = result["resolution_v"]
    differ = sum(s["precision"]["differ"] for s in result["starts"])
    words = sum(s["precision"]["words"] for s in result["starts"])
    worst = max(s["precision"]["max_codes"] for s in result["starts"])
    out.append(
        f"Causes, measured one at a time with the Python law over the {len(kept)} starts every form held: the "
        f"board's input step is {1e3 * r['firmware']:.2f} mV against the card's {1e3 * r['python']:.2f} mV "
        f"(quantization); the firmware's longest update is {1e3 * result['delay_s']:g} ms of output delay (timing); "
        f"replayed through the law in double precision, {differ} of the firmware's {words} DAC words change, by at "
        f"most {worst} code{'s' if worst != 1 else ''} (precision: "
        f"{'none' if not differ else 'a code is ' + format(1e3 * result['dac_step_v'], '.2f') + ' mV at the DAC'})."
        " What the single causes leave is the firmware's own sampling: sixteen conversions at its period's start, "
        "not the card's last sample and block mean, so the contact noise reaches it at other instants."
    )
    if "c" in result["starts"][0]["forms"]:
        same = all(s["forms"]["c"] == s["forms"]["python"] for s in result["starts"])
        out.append(
            ""
            if not same
            else "The C client on the PC gives the Python form's records bit for bit (the same double arithmetic)."
        )
    for key, scale, unit, name in FIGURES:
        if not kept:
            break

        def mean(form: str) -> float:
            return float(np.mean([s["forms"][form][key] for s in kept])) * scale  # noqa: B023

        base, fw = mean("python"), mean("firmware")
        alone = {cause: mean(cause) - base for cause in ("quantization", "timing")}
        parts = [f"{cause} alone {delta:+.2f} {unit}" for cause, delta in alone.items()]
        change = f"Python {base:+.2f} {unit}, firmware {fw:+.2f} {unit} ({fw - base:+.2f})"
        rest = fw - base - sum(alone.values())
        out.append(f"- {name}: {change}; " + "; ".join(parts) + f"; the rest {rest:+.2f} {unit}")
    return [line for line in out if line]
