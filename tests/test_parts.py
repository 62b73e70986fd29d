"""The rig's parts as contracts (twin.parts): every registered part keeps its contract (parameters with units,
bounds and sources; equations at their homes; its MJCF fragment in the compiled model and written from its
parameters; its batch form equal to its one-run form), today's rig is the composition of today's parts bit for
bit, and a part written from the contract alone takes a role in a rig that then holds the ball."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import mujoco
import numpy as np
import pytest

from controllers import registry
from twin.engine import ClosedLoop, update_ticks
from twin.model import build_model, build_spec
from twin.parameters import GROUPS, ParameterError, Parameters, check_group, param
from twin.parts import (
    ROLES,
    THESIS,
    BallSensorPart,
    BatchForm,
    MjcfFragment,
    Part,
    PartError,
    contract,
    register,
    registered,
)
from twin.parts.thesis import NOT_PART_GROUPS
from twin.physics import PhysicsBlock
from twin.rigs.sim import SimRig


def _blob(model: mujoco.MjModel) -> bytes:
    buf = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    return buf.tobytes()


# --- the invariants every part keeps (dm_control style: one check per property, over every part) ----------
def _parameter_problems(part: Part) -> list[str]:
    problems = []
    if not part.groups:
        problems.append("declares no parameter group")
    for group, cls in part.groups.items():
        for f in fields(cls):
            md, name = f.metadata, f"{group}.{f.name}"
            if not md.get("unit") or not md.get("source"):
                problems.append(f"{name}: no unit or no source")
            if md.get("flag"):
                continue
            if md.get("curve"):
                if not md.get("magnitude"):
                    problems.append(f"{name}: a curve without a magnitude bound")
                continue
            lower = md.get("gt") is not None or md.get("ge") is not None
            upper = md.get("lt") is not None or md.get("le") is not None
            if not (lower and upper and md.get("why")):
                problems.append(f"{name}: not bounded on both sides with a reason")
        try:
            cls()
        except ParameterError as exc:
            problems.append(f"{group}: its defaults are refused ({exc})")
    return problems


def _home_module(part: Part) -> str | None:
    """The module under twin.parts that defines ``part`` (the thesis's parts point at the core: None)."""
    import sys

    for name, module in list(sys.modules.items()):
        if name.startswith("twin.parts.") and name != "twin.parts.thesis":
            if any(value is part for value in vars(module).values()):
                return name
    return None


def _defines_parts(module_name: str) -> bool:
    """Whether a module under twin.parts defines a part (or is the contract): not a home of shared equations."""
    import sys

    module = sys.modules[module_name]
    return module_name == "twin.parts.contract" or any(isinstance(v, Part) for v in vars(module).values())


def _equation_problems(part: Part, *, own_home: bool) -> list[str]:
    problems = [f"{eq!r} is not callable" for eq in part.equations if not callable(eq)]
    problems += [f"{eq!r} has no docstring" for eq in part.equations if not (eq.__doc__ or "").strip()]
    if own_home:  # a part's equations live in the core, its own module or a module of shared equations
        home = _home_module(part)  # (twin.parts.ranging), never in another part's module
        problems += [
            f"{eq!r} lives in {eq.__module__}"
            for eq in part.equations
            if eq.__module__.startswith("twin.parts")
            and eq.__module__ != home
            and _defines_parts(eq.__module__)
        ]
    return problems or ([] if part.equations else ["names no equation"])


def _check_part(part: Part, seed: int, *, own_home: bool = True) -> None:
    assert part.name and part.source and part.role in ROLES
    assert isinstance(part, contract.ROLE_TYPES[part.role])
    assert not _parameter_problems(part), _parameter_problems(part)
    assert not _equation_problems(part, own_home=own_home), _equation_problems(part, own_home=own_home)
    # its elements are in the model of the thesis's rig with this part in its role
    model = build_model(Parameters().with_overrides({f"parts.{part.role}": part.name}))
    assert not part.mjcf.missing(model), part.mjcf.missing(model)
    assert part.batch.difference(np.random.default_rng(seed), 24) <= part.batch.tolerance


@pytest.mark.quick
@pytest.mark.parametrize("part", registered(), ids=lambda p: f"{p.role}:{p.name}")
def test_every_registered_part_keeps_its_contract(part: Part) -> None:
    _check_part(part, seed=20261207)


@pytest.mark.quick
def test_every_role_has_todays_part_and_every_parameter_group_one_owner() -> None:
    assert [p.role for p in THESIS] == list(ROLES)
    assert all(registered(role) and registered(role)[0] is getattr(THESIS, role) for role in ROLES)
    owners: dict[str, list[str]] = {}
    for part in THESIS:
        for group, cls in part.groups.items():
            assert GROUPS[group] is cls  # the table's own class: the part points at it, copies no numbers
            owners.setdefault(group, []).append(part.name)
    assert all(len(names) == 1 for names in owners.values()), owners
    assert set(owners).isdisjoint(NOT_PART_GROUPS)
    assert set(owners) | set(NOT_PART_GROUPS) == set(GROUPS)
    assert all(why for why in NOT_PART_GROUPS.values())


@pytest.mark.quick
def test_the_fragments_are_disjoint_and_each_writes_its_parts_parameters() -> None:
    seen: set[tuple[str, str]] = set()
    for part in THESIS:
        assert seen.isdisjoint(part.mjcf.elements), part.name
        seen |= set(part.mjcf.elements)
    base = _blob(build_model())
    for part in (p for p in THESIS if p.mjcf.apply is not None):
        group, cls = next(iter(part.groups.items()))
        changed = [
            f.name
            for f in fields(cls)
            if not f.metadata.get("flag") and not f.metadata.get("curve") and getattr(cls(), f.name) != 0
            and _blob(build_model(Parameters().with_overrides({f"{group}.{f.name}": getattr(cls(), f.name) * 1.01})))
            != base
        ]  # fmt: skip
        assert changed, f"{part.name}: its fragment writes none of {group}'s values"


@pytest.mark.quick
def test_a_fragment_names_what_the_model_lacks() -> None:
    fragment = MjcfFragment((("body", "ball"), ("geom", "no_such_geom"), ("tendon", "ball")))
    assert fragment.missing(build_model()) == ["geom 'no_such_geom'", "tendon 'ball'"]


@pytest.mark.quick
def test_a_batch_form_that_drops_each_runs_parameters_is_caught() -> None:
    good = THESIS.actuator.batch

    def shared(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
        return good.batch([params[0]] * len(params), rows)  # every run with the first run's motor

    broken = dataclasses.replace(good, batch=shared)
    assert good.difference(np.random.default_rng(1), 16) == 0.0
    assert broken.difference(np.random.default_rng(1), 16) > 1e-3


# --- today's rig is the composition of today's parts -----------------------------------------------------
@pytest.mark.quick
@pytest.mark.parametrize(
    "overrides", [{}, {"ball.radius_m": 0.01, "beam.pivot_friction_nm": 0.01, "motor.gear_ratio": 9.0}]
)
def test_the_parts_fragments_compose_the_twins_model_bit_for_bit(overrides: dict[str, float]) -> None:
    p = Parameters().with_overrides(overrides)
    for hold in (None, 0.1):
        assert _blob(THESIS.build_spec(p, hold_beam_rad=hold).compile()) == _blob(
            build_model(p, hold_beam_rad=hold)
        )
        assert THESIS.build_spec(p, hold_beam_rad=hold).to_xml() == build_spec(p, hold_beam_rad=hold).to_xml()


@pytest.mark.quick
def test_the_rig_runs_todays_parts_and_its_write_is_the_output_stages() -> None:
    from twin.output_stage import motor_volts

    rig = SimRig(Parameters(), seed=3)
    assert rig.parts == THESIS  # the parts Parameters() names (twin.parts.rig_parts)
    commands = np.random.default_rng(5).uniform(-1.0, 6.0, 200)
    write = THESIS.motor_volts_of(rig.params)
    assert [write(c) for c in commands.tolist()] == np.asarray(motor_volts(commands, rig.params)).tolist()
    default, explicit = SimRig(seed=3), SimRig(seed=3, parts=THESIS)
    for r in (default, explicit):
        r.reset(0.1, 0.05)
        r.write(3.0)
    assert [default.read() for _ in range(30)] == [explicit.read() for _ in range(30)]


# --- the registry refuses parts that break the contract ---------------------------------------------------
@pytest.fixture
def fresh_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """The registry as it is, restored after the test (a test's registrations do not leak)."""
    monkeypatch.setattr(
        contract, "_REGISTRY", {role: dict(parts) for role, parts in contract._REGISTRY.items()}
    )


@pytest.mark.quick
@pytest.mark.usefixtures("fresh_registry")
def test_the_registry_refuses_a_second_name_a_wrong_type_and_an_unknown_role() -> None:
    with pytest.raises(PartError, match="a ball_sensor named 'resistive_wire' is registered already"):
        register(THESIS.ball_sensor)
    plain = dataclasses.replace(THESIS.ball, name="plain", role="ball_sensor")
    with pytest.raises(
        PartError, match="'plain' \\(Part\\) cannot be a ball_sensor: that role needs a BallSensorPart"
    ):
        register(plain)
    with pytest.raises(PartError, match="role 'wheel' is not one of"):
        register(dataclasses.replace(THESIS.ball, name="odd", role="wheel"))  # type: ignore[arg-type]
    with pytest.raises(PartError, match="role 'wheel' is not one of"):
        registered("wheel")  # type: ignore[arg-type]
    with pytest.raises(PartError, match="part 'steel_ball' is a ball, not a track"):
        dataclasses.replace(THESIS, track=THESIS.ball)


# --- a part written from the contract alone ---------------------------------------------------------------
@dataclass(frozen=True)
class IdealWiper:
    """A toy ball sensor's parameter group: the ball's position read exactly, at a gain of its own."""

    gain_v_per_m: float = param(
        20.0,
        "V/m",
        "a toy: an exact position sensor, 20 V/m (the thesis's wire reads about 14.4 V/m)",
        gt=0.0,
        le=1000.0,
        why="1000 V/m puts a 10 mm step at 10 V, the card's whole range",
    )

    def __post_init__(self) -> None:
        check_group(self, "ideal_wiper")


class IdealWiperChain:
    """The toy's chain: the board reads gain·x at the block's end, the pin sees it at once, nothing else."""

    def __init__(self, group: IdealWiper) -> None:
        self.gain = group.gain_v_per_m
        self.reading_v = self.filtered_v = 0.0

    @property
    def dropout_count(self) -> int:
        return 0

    def reset(
        self,
        x_m: float,
        t_s: float = 0.0,
        *,
        in_contact: bool = True,
        seed: int | np.random.Generator | None = None,
    ) -> None:
        self.reading_v = self.filtered_v = self.gain * x_m

    def set_params(self, params: Parameters) -> None:
        pass

    def advance(self, times_s: np.ndarray, x_m: np.ndarray, in_contact: bool | np.ndarray = True) -> float:
        self.reading_v = self.filtered_v = self.gain * float(x_m[-1])
        return self.reading_v

    def advance_block(self, block: PhysicsBlock) -> float:
        return self.advance(block.time_s, block.x_m)

    def advance_rig_block(
        self,
        times_s: np.ndarray,
        x_m: np.ndarray,
        in_contact: np.ndarray,
        equal_steps: bool,
        x_range_m: tuple[float, float] | None = None,
        all_on_track: bool | None = None,
    ) -> float:
        return self.advance(times_s, x_m)


def ideal_wiper(group: IdealWiper) -> BallSensorPart:
    """The toy part: its group, its equation (the chain), no MJCF, a batch form (gain·x over every run)."""

    def single(params: Parameters, row: np.ndarray) -> np.ndarray:
        chain = IdealWiperChain(group)
        return np.array([chain.advance(np.array([0.0, 0.02]), row)])

    def batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
        return group.gain_v_per_m * rows[:, -1:]

    def inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
        return [Parameters()] * n, rng.uniform(-0.3, 0.3, (n, 2))

    return BallSensorPart(
        name="ideal_wiper",
        source="a test's toy",
        groups={"ideal_wiper": IdealWiper},
        equations=(IdealWiperChain,),
        mjcf=MjcfFragment(),
        batch=BatchForm(single, batch, inputs, "tests/test_parts.py"),
        chain=lambda params, seed: IdealWiperChain(group),
    )


@pytest.mark.quick
@pytest.mark.usefixtures("fresh_registry")
def test_a_part_written_from_the_contract_alone_takes_its_role_and_the_rig_holds_the_ball() -> None:
    group = IdealWiper()
    part = register(ideal_wiper(group))
    _check_part(part, seed=7, own_home=False)
    assert registered("ball_sensor")[-1] is part
    rig_parts = THESIS.replace(part)
    assert rig_parts.ball_sensor is part and rig_parts.angle_sensor is THESIS.angle_sensor
    # the controller converts the card's volts with the software's calibration: the toy's gain, no offset
    params = Parameters().with_overrides(
        {"software.ball_gain_m_per_v": 1.0 / group.gain_v_per_m, "software.ball_offset_m": 0.0}
    )
    rig = SimRig(params, seed=0, parts=rig_parts)
    rig.reset(0.1, 0.0)
    loop = ClosedLoop(rig, registry.make("appendix-sf", params))
    loop.run(update_ticks(3.0, params), stop_when_lost=True)
    log = loop.log()
    assert not rig.ball_lost
    assert np.array_equal(log.datam1, group.gain_v_per_m * log.true_x_m)  # the toy's law, exactly
    assert abs(float(log.true_x_m[-1])) < 0.01  # held: from 100 mm back to within 10 mm of the centre
    assert math.isfinite(float(log.aout[-1]))


@pytest.mark.quick
def test_a_parts_own_group_refuses_a_value_naming_the_field() -> None:
    with pytest.raises(
        ParameterError, match=r"ideal_wiper.gain_v_per_m = -1.0 V/m is impossible: it must be > 0.0"
    ):
        IdealWiper(gain_v_per_m=-1.0)
