"""The physics backends' registry (twin.rigs.backends): a backend written from the contract alone is one row away from
the many-run commands, the registry's refusals name the choices, the engine's words map onto a screening policy
in one place, and no module outside the registry picks a backend by comparing its name.

The backend here is written from the equations of motion (docs/design.md; twin/reference.py's docstring,
eq 3.1.26/3.1.27 and the motor's eq 3.3.1) with numpy alone: classical RK4 at the physics step, the volts held
over a step through the amplifier's rails, the beam's stops inelastic, the ball lost past the track's end. It
shares no code with the reference plant, so it agrees with it to rounding only (``TOLERANCE``)."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pytest

from twin.parameters import Parameters
from twin.physics import BatchBlock, PhysicsBlock, check_initial_state
from twin.rigs.backends import (
    Backend,
    BackendError,
    ScreeningPolicy,
    backend,
    engine_policy,
    label_backend,
    plant_choices,
    register,
    unregister,
)

ROOT = Path(__file__).resolve().parent.parent
NAME = "numpy-rk4"
# What the reference plant and an independent RK4 of the same equations at the same step may differ by in a
# verdict's figures: rounding (a different order of operations) grown over a run, far below a millimetre.
TOLERANCE = 1e-6


class _Equations:
    """The coefficients of eq 3.1.26/3.1.27 and the rig's limits for N parameter sets, (N,) arrays."""

    def __init__(self, params: Sequence[Parameters]) -> None:
        def col(f: object) -> np.ndarray:
            return np.array([f(p) for p in params], dtype=float)  # type: ignore[operator]

        m = col(lambda p: p.ball.mass_kg)
        r = col(lambda p: p.ball.radius_m)
        h = col(lambda p: p.track.contact_height_m)
        d = col(lambda p: p.track.contact_spacing_m)
        rs = np.sqrt(r**2 - d**2 / 4)  # r*: the ball centre above the wires' contact line
        g = col(lambda p: p.physics.gravity_m_s2)
        n2 = col(lambda p: p.motor.gear_ratio) ** 2
        self.k1 = 2 * r**2 / (5 * rs**2)
        self.k2 = 2 * r**2 / (5 * rs)
        self.c = h + rs
        self.g = g
        self.a1 = self.k1 * m * h
        self.a2 = col(lambda p: p.beam.inertia_pivot_kgm2) + col(lambda p: p.motor.rotor_inertia_kgm2) * n2
        self.a2 = self.a2 - self.k2 * m * h
        self.a3 = m
        self.b1 = -col(lambda p: p.beam.mass_kg) * g * col(lambda p: p.beam.cog_height_m)
        self.b2, self.b3, self.b4 = m * g, 2 * m, -m * self.c
        self.b5 = col(lambda p: p.motor.viscous_damping_nm_s_per_rad) * n2
        self.b5 = self.b5 + col(lambda p: p.beam.pivot_damping_nm_s_per_rad)
        self.dry = col(lambda p: p.beam.pivot_friction_nm)
        self.k_tau = col(lambda p: p.motor.torque_per_volt_nm_per_v)
        self.k_b = col(lambda p: p.motor.backemf_at_beam_v_s_per_rad)
        self.rail = col(lambda p: p.amplifier.rail_v)
        self.stop = col(lambda p: p.beam.stop_angle_rad)
        self.half = col(lambda p: p.track.half_length_m)

    def derivative(self, s: np.ndarray, v: np.ndarray, rows: np.ndarray) -> np.ndarray:
        x, th, xd, thd = s.T
        q = {k: a[rows] for k, a in vars(self).items()}
        torque = q["k_tau"] * (v - q["k_b"] * thd)
        friction = q["dry"] * np.clip(thd / 0.01, -1.0, 1.0)  # 0.01 rad/s: the regularization of sign(θ̇)
        lhs = np.empty((len(x), 2, 2))
        lhs[:, 0, 0], lhs[:, 0, 1] = 1 + q["k1"], -(q["k2"] + q["c"])
        lhs[:, 1, 0], lhs[:, 1, 1] = q["a1"], q["a2"] + q["a3"] * x**2
        rhs = np.stack(
            [
                x * thd**2 - q["g"] * np.sin(th),
                torque
                - q["b1"] * np.sin(th)
                - q["b2"] * x * np.cos(th)
                - q["b3"] * x * xd * thd
                - q["b4"] * x * thd**2
                - q["b5"] * thd
                - friction,
            ],
            axis=1,
        )
        acc = np.linalg.solve(lhs, rhs[:, :, None])[:, :, 0]
        return np.column_stack([xd, thd, acc[:, 0], acc[:, 1]])


class NumpyBatch:
    """``twin.physics.BatchPhysics`` of the equations above, numpy over the runs."""

    def __init__(
        self, params: Sequence[Parameters], x0: np.ndarray, theta0: np.ndarray, nthread: int
    ) -> None:
        for i, p in enumerate(params):
            check_initial_state(p, float(x0[i]), float(theta0[i]), 0.0, 0.0)
        self.eq = _Equations(params)
        self.h = params[0].physics.timestep_s
        self.states = np.column_stack([x0, theta0, np.zeros(len(params)), np.zeros(len(params))])
        self._lost = np.zeros(len(params), dtype=bool)
        self._lost_time_s: list[float | None] = [None] * len(params)
        self._time_s = 0.0

    @property
    def time_s(self) -> float:
        return self._time_s

    @property
    def lost(self) -> np.ndarray:
        return self._lost

    @property
    def lost_time_s(self) -> list[float | None]:
        return self._lost_time_s

    def advance(self, runs: np.ndarray, volts: np.ndarray) -> BatchBlock:
        h, eq, m = self.h, self.eq, volts.shape[1]
        s = self.states[runs].copy()
        xs, ths = np.empty((len(runs), m + 1)), np.empty((len(runs), m + 1))
        on = np.ones((len(runs), m + 1), dtype=bool)
        going = ~self._lost[runs]
        on[~going] = False
        xs[:, 0], ths[:, 0] = s[:, 0], s[:, 1]
        for k in range(m):
            idx = np.flatnonzero(going)
            if idx.size:
                rows = runs[idx]
                v = np.clip(volts[idx, k], -eq.rail[rows], eq.rail[rows])
                y = s[idx]
                k1 = eq.derivative(y, v, rows)
                k2 = eq.derivative(y + h / 2 * k1, v, rows)
                k3 = eq.derivative(y + h / 2 * k2, v, rows)
                k4 = eq.derivative(y + h * k3, v, rows)
                y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
                past = np.abs(y[:, 1]) > eq.stop[rows]  # the stops: inelastic
                y[past, 1] = np.sign(y[past, 1]) * eq.stop[rows][past]
                y[past & (y[:, 3] * y[:, 1] > 0), 3] = 0.0
                s[idx] = y
                off = np.abs(y[:, 0]) > eq.half[rows]
                for j in idx[off].tolist():
                    self._lost[runs[j]] = True
                    self._lost_time_s[runs[j]] = self._time_s + (k + 1) * h
                    on[j, k + 1 :] = False
                going[idx[off]] = False
            xs[:, k + 1], ths[:, k + 1] = s[:, 0], s[:, 1]
        self.states[runs] = s
        times = self._time_s + np.arange(m + 1) * h
        self._time_s = float(times[-1])
        return BatchBlock(times, xs, ths, on)

    def true_state(self, runs: np.ndarray) -> np.ndarray:
        return self.states[runs].copy()


class NumpyPlant:
    """``twin.physics.PhysicsBackend``: one run of ``NumpyBatch``."""

    def __init__(self, params: Parameters) -> None:
        self.params = params
        self.reset(0.0, 0.0)

    @property
    def time_s(self) -> float:
        return self.batch.time_s

    @property
    def timestep_s(self) -> float:
        return self.params.physics.timestep_s

    @property
    def ball_lost(self) -> bool:
        return bool(self.batch.lost[0])

    @property
    def ball_lost_time_s(self) -> float | None:
        return self.batch.lost_time_s[0]

    def reset(self, x_m: float, theta_rad: float, xdot_m_s: float = 0.0, thetadot_rad_s: float = 0.0) -> None:
        check_initial_state(self.params, x_m, theta_rad, xdot_m_s, thetadot_rad_s)
        self.batch = NumpyBatch([self.params], np.array([x_m]), np.array([theta_rad]), 1)
        self.batch.states[0, 2:] = xdot_m_s, thetadot_rad_s

    def advance(self, motor_volts: np.ndarray) -> PhysicsBlock:
        b = self.batch.advance(np.array([0]), np.asarray(motor_volts, dtype=float).reshape(1, -1))
        return PhysicsBlock(b.time_s, b.x_m[0], b.theta_rad[0], b.on_track[0])

    def advance_held(self, motor_volts: float, n_steps: int) -> PhysicsBlock:
        return self.advance(np.full(n_steps, float(motor_volts)))

    def state(self) -> np.ndarray:
        return self.batch.true_state(np.array([0]))[0]

    def kick_ball(self, dv_m_s: float) -> None:
        if not self.ball_lost:
            self.batch.states[0, 2] += dv_m_s


ROW = Backend(
    name=NAME,
    single=NumpyPlant,
    batch=NumpyBatch,
    exact=False,
    summary="the reference model's equations in numpy (a test's backend)",
    label=NAME,
    ideal_converters=True,
)


@pytest.fixture
def registered() -> Iterator[Backend]:
    register(ROW)
    try:
        yield ROW
    finally:
        unregister(NAME)


def _cli_json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> dict:
    from twin.app.cli import main

    capsys.readouterr()
    code = main(argv)
    out, err = capsys.readouterr()
    assert code in (0, 1), err
    return json.loads(out)


def test_the_contract_alone_steps_as_the_reference_kernel(registered: Backend) -> None:
    """The test's batch against the reference backend's batch (the compiled kernel) under the same volts: to
    rounding, the same lost runs at the same steps, both through the registry's rows."""
    rng = np.random.default_rng(3)
    n = 12
    params = [Parameters().with_overrides({"beam.pivot_friction_nm": 0.002 * (i % 3)}) for i in range(n)]
    x0, th0 = rng.uniform(-0.3, 0.3, n), rng.uniform(-0.5, 0.5, n)
    volts = rng.uniform(-3.0, 3.0, (n, 400)) * np.linspace(0.0, 1.0, n)[:, None]
    ours, ref = backend(NAME).batch(params, x0, th0, 1), backend("reference").batch(params, x0, th0, 1)
    runs = np.arange(n)
    for chunk in np.split(volts, 4, axis=1):
        a, b = ours.advance(runs, chunk), ref.advance(runs, chunk)
        np.testing.assert_array_equal(a.time_s, b.time_s)
        np.testing.assert_allclose(a.x_m, b.x_m, atol=1e-9, rtol=0)
        np.testing.assert_allclose(a.theta_rad, b.theta_rad, atol=1e-9, rtol=0)
        np.testing.assert_array_equal(a.on_track, b.on_track)
    np.testing.assert_allclose(ours.true_state(runs), ref.true_state(runs), atol=1e-9, rtol=0)
    np.testing.assert_array_equal(ours.lost, ref.lost)
    assert 0 < ours.lost.sum() < n  # both cases compared
    assert ours.lost_time_s == ref.lost_time_s


def _points(result: dict) -> list[dict]:
    return result["points"]


def test_a_backend_from_the_contract_runs_sweep_and_montecarlo(
    registered: Backend, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """One registry row: ``--plant numpy-rk4`` is a choice, and ``sweep`` and ``montecarlo`` run on it and
    agree with the reference backend's runs to ``TOLERANCE`` (each verdict's class and figures)."""
    grid = ["--x0=-0.2:0.2:3", "--theta0=-0.3:0.3:2", "--duration", "3", "--json"]
    sweeps = {
        plant: _cli_json(capsys, ["sweep", "--controller", "appendix-sf", "--plant", plant, *grid])
        for plant in (NAME, "reference")
    }
    ours, ref = _points(sweeps[NAME]), _points(sweeps["reference"])
    assert len(ours) == len(ref) == 6
    assert {p["engine"] for p in ours} == {NAME} and {p["engine"] for p in ref} == {"reference"}
    _agree(ours, ref)
    spread = tmp_path / "spread.toml"
    spread.write_text(
        "[motor]\nresistance_ohm = { rel_sd = 0.05 }\n[beam]\npivot_friction_nm = { low = 0.0, high = 0.004 }\n"
    )
    mc = ["montecarlo", "--controller", "appendix-sf", "--n", "4", "--spread", str(spread), "--duration", "3"]
    runs = {
        plant: _cli_json(capsys, [*mc, "--plant", plant, "--json"])["runs"] for plant in (NAME, "reference")
    }
    assert len(runs[NAME]) == len(runs["reference"]) == 4
    _agree(runs[NAME], runs["reference"])
    assert [r["parameters"] for r in runs[NAME]] == [r["parameters"] for r in runs["reference"]]


def _agree(ours: list[dict], ref: list[dict]) -> None:
    assert any(b.get("steady_x_m") is not None for b in ref)  # figures compared, not only classes
    for a, b in zip(ours, ref, strict=True):
        for key in ("held", "ball_lost"):
            assert a[key] == b[key], (key, a, b)
        for key in ("steady_x_m", "settling_time_s"):
            if b.get(key) is None:
                assert a.get(key) is None, (key, a, b)
            else:
                assert abs(a[key] - b[key]) <= TOLERANCE, (key, a[key], b[key])


@pytest.mark.quick
def test_the_registry_names_its_rows_and_refuses_others(registered: Backend) -> None:
    assert plant_choices()[0] == "twin" and {"reference", NAME} <= set(plant_choices())
    assert backend("twin").exact and not backend("reference").exact and not backend(NAME).exact
    with pytest.raises(
        BackendError, match=r"plant = 'simulink': expected one of 'twin', 'numpy-rk4', 'reference'"
    ):
        backend("simulink")
    with pytest.raises(BackendError, match="registered already"):
        register(ROW)
    with pytest.raises(BackendError, match="built in"):
        unregister("twin")
    assert label_backend("mujoco").name == "twin" and label_backend("fast").name == "reference"
    assert label_backend(NAME).name == NAME


@pytest.mark.quick
def test_the_engine_words_map_onto_one_policy() -> None:
    """``--engine`` screen | fast | mujoco as screening policies (twin.rigs.backends.engine_policy, the one map)."""
    assert engine_policy("screen") == ScreeningPolicy("reference", "twin", confirms=True)
    assert engine_policy("fast") == ScreeningPolicy("reference", "twin", confirms=False)
    assert engine_policy("mujoco") == ScreeningPolicy(None, "twin")
    assert engine_policy("screen").screened and not engine_policy("fast").screened
    assert engine_policy("fast").stand_alone and engine_policy("fast").decider == "reference"
    assert [engine_policy(e).decider_label() for e in ("screen", "fast", "mujoco")] == [
        "mujoco",
        "fast",
        "mujoco",
    ]
    assert engine_policy("mujoco", "reference").decider_label() == "reference"
    with pytest.raises(BackendError, match="the fast engine stands in for the MuJoCo twin; not with --plant"):
        engine_policy("screen", "reference")
    assert engine_policy("screen", "reference", strict=False) == ScreeningPolicy(None, "reference")
    with pytest.raises(BackendError, match="engine = 'gpu'"):
        engine_policy("gpu")


@pytest.mark.quick
def test_an_unregistered_plant_is_refused_on_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    from twin.app.cli import main

    assert main(["run", "--controller", "appendix-sf", "--plant", NAME]) == 2
    err = capsys.readouterr().err
    assert f"invalid choice: '{NAME}'" in err and "'twin', 'reference'" in err and "Traceback" not in err


# A plant's or the engine's name compared as a string literal (either quote), or the old plant literal type.
COMPARISON = re.compile(
    r"""[=!]=\s*(['"])(twin|reference|screen|fast)\1"""
    r"""|(['"])(twin|reference|screen|fast)\3\s*[=!]="""
    r"""|Literal\[\s*(['"])(twin|reference)\5"""
)
MEMBERSHIP = re.compile(r"""\bin\s+\(\s*(['"])(twin|reference|screen|fast)\1""")
LOOP = re.compile(r"\bfor\s+\w+\s+in\s+\(")  # iterating over names is not choosing by one


@pytest.mark.quick
def test_no_module_outside_the_registry_compares_plant_names() -> None:
    """Every backend choice is a registry lookup: no ``== "twin"``, ``!= "reference"``, ``in ("twin", …)``,
    ``== "screen"``/``"fast"`` and no ``PlantKind`` use in twin/ and scripts/ but twin/rigs/backends.py (and the
    lazy re-export of ``PlantKind`` in twin/rigs/__init__.py)."""
    found = []
    for path in sorted([*(ROOT / "twin").rglob("*.py"), *(ROOT / "scripts").rglob("*.py")]):
        rel = path.relative_to(ROOT).as_posix()
        if rel == "twin/rigs/backends.py":
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            compared = COMPARISON.search(line) or (MEMBERSHIP.search(line) and not LOOP.search(line))
            if compared or ("PlantKind" in line and rel != "twin/rigs/__init__.py"):
                found.append(f"{rel}:{n}: {line.strip()}")
    assert not found, "\n".join(found)


@pytest.mark.quick
def test_reading_the_table_loads_no_physics() -> None:
    """``--plant``'s choices come from the table when any parser is built: reading it imports no numpy."""
    import subprocess
    import sys

    code = (
        "import sys\nfrom twin.rigs.backends import plant_choices, plant_help\nplant_choices(); plant_help()\n"
        "print(sorted(m for m in ('numpy', 'mujoco', 'numba') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "[]", (out.stdout, out.stderr)


@pytest.mark.quick
def test_the_twin_batch_is_each_plant_alone_bit_for_bit() -> None:
    """The twin's row: its batch (``MujocoBatchPhysics``) steps each run as ``Plant`` alone, block by block."""
    from twin.plant import Plant
    from twin.plant_batch import MujocoBatchPhysics

    params = [Parameters()] * 2
    x0, th0 = np.array([0.1, -0.2]), np.array([0.0, 0.1])
    batch = backend("twin").batch(params, x0, th0, 1)
    assert isinstance(batch, MujocoBatchPhysics)
    volts = np.linspace(-2.0, 2.0, 60).reshape(2, 30)
    alone = [Plant(p) for p in params]
    for i, plant in enumerate(alone):
        plant.reset(float(x0[i]), float(th0[i]))
    for chunk in np.split(volts, 2, axis=1):
        block = batch.advance(np.arange(2), chunk)
        for i, plant in enumerate(alone):
            single = plant.advance(chunk[i])
            np.testing.assert_array_equal(block.time_s, single.time_s)
            np.testing.assert_array_equal(block.x_m[i], single.x_m)
            np.testing.assert_array_equal(block.theta_rad[i], single.theta_rad)
            np.testing.assert_array_equal(block.on_track[i], single.on_track)
    np.testing.assert_array_equal(batch.true_state(np.arange(2)), np.array([p.state() for p in alone]))
    assert batch.time_s == alone[0].time_s and not batch.lost.any()
