"""The same bits under any OpenBLAS kernel: the bit-pinning tests run in child processes with
``OPENBLAS_CORETYPE`` unset, Haswell, SkylakeX and Zen (set in the children's environment only; SkylakeX
only on a CPU with AVX-512), and the batch's logs hash the same in all. The tick's products are
``twin.fixedorder``'s: left to right, no BLAS (whose kernel chose the summation order and the fused
multiply-adds: the golden logs differed by one ulp between Haswell and SkylakeX)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from twin import fixedorder as fo

ROOT = Path(__file__).resolve().parents[1]
CORE_TYPES = (None, "Haswell", "SkylakeX", "Zen")
# What each kernel executes (numpy's names for the CPU's features): forced onto a CPU without them, OpenBLAS
# dies of an illegal instruction (SkylakeX's AVX-512 on an AVX2-only machine).
_KERNEL_NEEDS = {"Haswell": ("AVX2", "FMA3"), "SkylakeX": ("AVX512_SKX",), "Zen": ("AVX2", "FMA3")}


def _runs_here(core_type: str | None) -> bool:
    from numpy._core._multiarray_umath import __cpu_features__

    return core_type is None or all(__cpu_features__.get(f) for f in _KERNEL_NEEDS[core_type])


# The tests that pin bits: the golden digests, the first runner's logs, determinism, batch = single, the 1 kHz
# laws' float path, the ball filter's equalities.
BIT_PINNING = [
    "tests/test_engine.py::test_runs_are_bit_for_bit_those_recorded_before_the_per_tick_work",
    "tests/test_engine.py::test_the_engine_reproduces_the_first_runners_logs",
    "tests/test_engine.py::test_same_seed_same_log_different_seed_different_log",
    "tests/test_batch.py",
    "tests/test_state_law_speedpath.py",
    "tests/test_sensors.py::test_rig_block_filter_equals_the_piecewise_filter",
    "tests/test_sensors.py::test_rc_filter_is_exact_against_an_ode_solver",
    "tests/test_portability.py::test_fixed_order_products",
    "tests/test_screen.py",
]

# A batch of runs (vectorized controllers, the scalar loop, a lost ball) hashed, printed by each child.
_BATCH_DIGEST = """
import hashlib
import numpy as np
from controllers import registry
from twin.rigs.batch import run_batch
from threadpoolctl import threadpool_info

digest = hashlib.sha256()
for name, vectorized in (("appendix-sf", True), ("appendix-clp", True), ("thesis-sf", True), ("thesis-clp", True),
                         ("thesis-clp", False)):
    runs = run_batch(registry, name, x0_m=np.array([0.14, -0.13, 0.25]), theta0_rad=np.array([-0.2, 0.29, -0.7]),
                     seeds=np.array([0, 1, 2]), duration_s=3.0, record=True, nthread=1, vectorized=vectorized)
    for run in runs:
        for value in vars(run.log).values():
            digest.update(np.ascontiguousarray(value).tobytes())
        digest.update(repr(run.verdict.to_json()).encode())
# the fast engine (the compiled reference plant under the same chain)
for name in ("appendix-sf", "appendix-clp"):
    runs = run_batch(registry, name, x0_m=np.array([0.14, -0.13, 0.25]), theta0_rad=np.array([-0.2, 0.29, -0.7]),
                     seeds=np.array([0, 1, 2]), duration_s=3.0, record=True, plant="reference")
    for run in runs:
        for value in vars(run.log).values():
            digest.update(np.ascontiguousarray(value).tobytes())
        digest.update(repr(run.verdict.to_json()).encode())
# the ball chain's filter voltage (not logged: only its ADC reading is), block after block, with dropouts
from twin.parameters import Parameters
from twin.sensors import BallPositionChain

params = Parameters().with_overrides({"ball_sensor.dropout_rate_hz": 120.0})
chain = BallPositionChain(params, seed=4, x_m=0.05)
knots = np.arange(21) * 1e-3
for k in range(300):
    times = 0.02 * k + knots
    chain.advance_rig_block(times, 0.05 + 0.1 * np.sin(3 * times), np.ones(21, dtype=bool), True)
    digest.update(np.float64(chain.filtered_v).tobytes())
# a falsification over a spread (a Sobol batch, the linear model's corner, CMA-ES's generations): its points and
# objectives
import json
from twin.app.falsify import FalsifySettings, falsify
from twin.app.montecarlo import load_spread
from twin.requirements import load_spec

spread = load_spread("docs/examples/spread.toml", Parameters())
search = FalsifySettings("appendix-sf", (), x0_m=0.12, theta0_rad=-0.5, duration_s=1.0, budget=120, population=8,
                         keep_going=True)
found = falsify(search, Parameters(), load_spec("docs/examples/falsify.toml"), spread)
digest.update(json.dumps([(r["u"], r["objective"]) for r in found.runs]).encode())
print([i["architecture"] for i in threadpool_info() if i["internal_api"] == "openblas"], digest.hexdigest())
"""


def _env(core_type: str | None, **extra: str) -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1", **extra)
    env.pop("OPENBLAS_CORETYPE", None)
    if core_type is not None:
        env["OPENBLAS_CORETYPE"] = core_type
    return env


def _batch_digest(env: dict[str, str]) -> str:
    """The child's output: the OpenBLAS kernel that ran and the digest of the batch's logs."""
    batch = subprocess.run(
        [sys.executable, "-c", _BATCH_DIGEST], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600
    )
    assert batch.returncode == 0, batch.stderr[-2000:]
    return batch.stdout


@pytest.mark.quick
def test_fixed_order_products() -> None:
    """Left to right, each product rounded: (1e16 + 1) − 1e16 is 0 in that order, (1e16 − 1e16) + 1 is 1; a row of a
    batch has the bits of the float form."""
    assert fo.dot([1e16, 1.0, -1e16], [1.0, 1.0, 1.0]) == 0.0
    assert fo.dot([1e16, -1e16, 1.0], [1.0, 1.0, 1.0]) == 1.0
    assert fo.total([0.1, 0.2, 0.3]) == (0.1 + 0.2) + 0.3 == 0.6000000000000001
    rng = np.random.default_rng(5)
    a, m = rng.normal(size=(200, 21)), rng.normal(size=(200, 3, 21))
    w = rng.normal(size=21)
    rows = fo.dots(a, w)
    assert rows.tolist() == [fo.dot(r, w.tolist()) for r in a.tolist()]
    per_run = fo.matvecs(m, a)
    assert per_run.tolist() == [fo.matvec(mi, ai) for mi, ai in zip(m.tolist(), a.tolist(), strict=True)]
    shared = fo.matvecs(m[0], a)
    assert shared.tolist() == [fo.matvec(m[0].tolist(), ai) for ai in a.tolist()]
    # The sum is not numpy's pairwise add.reduce: on these rows the two disagree somewhere.
    assert (rows != (a * w).sum(axis=1)).any()


@pytest.mark.slow
def test_the_bit_pinning_tests_pass_under_every_openblas_kernel() -> None:
    """Under every kernel this CPU can execute (at least the default and one forced: Haswell and Zen need
    only AVX2 and FMA)."""
    digests = {}
    kernels = [c for c in CORE_TYPES if _runs_here(c)]
    assert len(kernels) >= 2, kernels
    for core_type in kernels:
        env = _env(core_type)
        tests = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "not slow", *BIT_PINNING],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert tests.returncode == 0, (core_type, tests.stdout[-3000:], tests.stderr[-2000:])
        printed = _batch_digest(env)
        digests[core_type] = printed.split()[-1]
        if core_type in ("Haswell", "SkylakeX"):  # the kernel asked for is the one that ran
            assert core_type in printed, printed
    assert len(set(digests.values())) == 1, digests


@pytest.mark.slow
def test_numpy_without_avx512_gives_the_same_bits() -> None:
    """Checked, not promised (README): numpy's AVX-512 code (its X86_V4 target) has other np.exp bits than
    its AVX2 code; the tick takes its exponentials from libm, so the logs and the ball filter's voltage are
    the same with that target disabled."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    disable = [
        f for f in ("AVX512_SPR", "AVX512_ICL", "X86_V4") if f in __cpu_dispatch__ and __cpu_features__.get(f)
    ]
    if "X86_V4" not in disable:
        pytest.skip("numpy's AVX-512 target does not run on this CPU")
    with_avx512 = _batch_digest(_env(None)).split()[-1]
    without = _batch_digest(_env(None, NPY_DISABLE_CPU_FEATURES=" ".join(disable))).split()[-1]
    assert without == with_avx512
