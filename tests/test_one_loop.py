"""One closed loop (docs/design.md, "One loop, many rigs"): a controller's ``update`` is called per tick in
``twin.engine`` (the loop every run goes through: in process, on a remote rig, served, the live view) and
in the batch (N runs at once) — nowhere else. Read from the source (``ast``), so a new loop written beside
them fails here; a controller that wraps another (its own ``update`` calls the inner one's once) is not a
loop.

And the loop needs only the ``Rig`` contract: a rig written here from the contract alone (no simulation
truth) runs a controller through it, judged from the volts it measured.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np

from twin.engine import ENDED_LAST_SAMPLE, ENDED_TICKS, ClosedLoop, run_on_rig
from twin.interface import Controller, DaqSample, Rig
from twin.parameters import Parameters
from twin.rigs.sim import make_rig, run_closed_loop

ROOT = Path(__file__).resolve().parent.parent
# The loop's home and the batch's: the only files that call a controller's update per tick.
LOOP_FILES = {"twin/engine.py", "twin/rigs/batch.py"}


def _sources() -> list[Path]:
    return sorted(p for pkg in ("twin", "controllers", "calib") for p in (ROOT / pkg).rglob("*.py"))


def _update_callers(paths: list[Path], root: Path = ROOT) -> dict[str, list[int]]:
    """Files (relative to ``root``) → lines that call a controller's ``update`` with a block: a call of
    ``checked_update`` or ``X.update(sample…)``, outside the ``update``/``start`` of a controller itself."""
    found: dict[str, list[int]] = {}
    for path in paths:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        wrappers = {
            id(node)
            for fn in ast.walk(tree)
            if isinstance(fn, ast.FunctionDef) and fn.name in ("update", "start")
            for node in ast.walk(fn)
        }
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call) or id(node) in wrappers:
                continue
            f = node.func
            named = isinstance(f, ast.Name) and f.id == "checked_update"
            method = (
                isinstance(f, ast.Attribute)
                and f.attr == "update"
                and len(node.args) == 1
                and isinstance(node.args[0], ast.Name)
                and node.args[0].id.startswith("sample")
            )
            if named or method:
                found.setdefault(str(path.relative_to(root)), []).append(node.lineno)
    return found


def test_only_the_loop_and_the_batch_call_a_controllers_update() -> None:
    callers = _update_callers(_sources())
    assert set(callers) == LOOP_FILES, callers


def test_the_scan_finds_a_loop_written_elsewhere_and_passes_a_wrapper(tmp_path: Path) -> None:
    """The scan is not blind: a loop like the one a remote client once had is found, a checked call too; a
    controller wrapping another is not a loop."""
    (tmp_path / "loop.py").write_text(
        "def run(c, rig):\n    while True:\n        sample = rig.read()\n        rig.write(c.update(sample))\n"
    )
    (tmp_path / "checked.py").write_text("def go(c, s):\n    return checked_update(c, s, '')\n")
    (tmp_path / "wrap.py").write_text(
        "class W:\n    def update(self, sample):\n        return self.inner.update(sample)\n"
    )
    found = _update_callers(sorted(tmp_path.glob("*.py")), tmp_path)
    assert found == {"loop.py": [4], "checked.py": [2]}


class _PlaybackRig(Rig):
    """A rig from the contract alone: it plays the blocks of a recorded run and takes commands, as a
    hardware backend would (no true state, a session that ends by itself)."""

    def __init__(self, samples: list[DaqSample], params: Parameters) -> None:
        self.samples, self.params = samples, params
        self.command_v = params.amplifier.zero_command_v
        self.written: list[float] = []
        self.k = -1

    @property
    def period_s(self) -> float:
        return self.params.daq.period_s

    def parameters(self) -> Parameters:
        return self.params

    def read(self) -> DaqSample:
        self.k += 1
        return self.samples[self.k]

    def write(self, command_v: float) -> None:
        self.command_v = command_v
        self.written.append(command_v)

    @property
    def is_last(self) -> bool:
        return self.k == len(self.samples) - 1


def _controller() -> Controller:
    from controllers import registry

    built = registry.make("appendix-sf", Parameters())
    assert isinstance(built, Controller)
    return built


def test_a_rig_from_the_contract_alone_runs_in_the_loop() -> None:
    """The blocks of a twin run played back through a rig that has only the contract: the same controller
    answers them with the same commands, the log is the rig software's (no true state), the run ends at
    the rig's last sample, and it is judged from the measured volts."""
    twin = run_closed_loop(_controller(), x0_m=0.1, theta0_rad=0.0, duration_s=2.0, seed=3)
    log = twin.log
    samples = [
        DaqSample(float(t), float(b), float(a))
        for t, b, a in zip(log.timem, log.datam1, log.datam2, strict=True)
    ]
    rig = _PlaybackRig(samples, Parameters())
    run = run_on_rig(_controller(), rig)
    assert run.ended == ENDED_LAST_SAMPLE
    assert rig.written == log.aout[1:].tolist()  # the same law on the same blocks: the same commands
    assert run.log.aout.tolist() == log.aout.tolist()
    assert run.log.true_x_m.size == 0  # no truth from a rig without it
    assert run.timing is not None and run.timing.ticks == len(samples) - 1
    measured = run.verdict
    assert measured.held == twin.verdict.held
    assert math.isclose(measured.duration_s, twin.verdict.duration_s, abs_tol=1e-9)


def test_the_loop_on_a_simulated_rig_records_its_true_state() -> None:
    rig = make_rig(Parameters(), seed=1)
    rig.reset(0.05, 0.0)
    loop = ClosedLoop(rig, _controller())
    assert loop.truth is rig
    assert loop.run(10) == ENDED_TICKS
    log = loop.log()
    assert log.timem.size == 11 and np.isfinite(log.true_x_m).all()
    assert log.true_x_m[0] == 0.05  # the held state
