"""The live view's seam between the GUI and the session: the session (``LiveTwin``) keeps the loop's state and
a typed set of commands; the GUI's handlers (twin.viewer.actions) check a control's input and reach the
session only through those commands (read from the source with ``ast``); a command called directly, without
any GUI, changes the state as the handler did."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from viewer_stubs import StubCatalogue

import twin.viewer.actions as actions
from twin.parameters import Parameters
from twin.viewer.actions import HANDLERS, Commands, Refused
from twin.viewer.session import LiveTwin

VIEWER = Path(actions.__file__).resolve().parent


def _commands() -> dict[str, ast.FunctionDef]:
    """The members the ``Commands`` protocol declares (its properties and its methods), by name."""
    tree = ast.parse(Path(actions.__file__).read_text(encoding="utf-8"))
    protocol = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Commands")
    return {n.name: n for n in protocol.body if isinstance(n, ast.FunctionDef)}


def _live(controller: str = "lqr") -> LiveTwin:
    return LiveTwin(Parameters(), StubCatalogue(), controller, seed=0, speed=1.0)  # type: ignore[arg-type]


@pytest.mark.quick
def test_the_session_class_holds_no_gui_handler() -> None:
    """No action table, no per-action handler and no method taking a GUI event or a raw GUI value, except
    the queue's own entry points; the session's module does not import viser."""
    assert not hasattr(LiveTwin, "_HANDLERS")
    assert not [name for name in vars(LiveTwin) if name.startswith("_do_")]
    queue = {"enqueue", "apply", "_apply", "_refuse"}  # (action, value) as queued: the seam's one door
    for name, member in vars(LiveTwin).items():
        if not inspect.isfunction(member):
            continue
        for param in list(inspect.signature(member).parameters.values())[1:]:
            annotation = str(param.annotation)
            assert param.name != "event" and "viser" not in annotation and "Gui" not in annotation, (
                name,
                param,
            )
            if name not in queue:
                assert annotation != "Any", f"LiveTwin.{name}({param.name}: Any) takes a raw value"
    tree = ast.parse((VIEWER / "session.py").read_text(encoding="utf-8"))
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not [m for m in imported if m.split(".")[0] == "viser"]


@pytest.mark.quick
def test_the_session_implements_every_command_with_the_same_signature() -> None:
    live = _live()
    for name, declared in _commands().items():
        member = inspect.getattr_static(LiveTwin, name, None)
        if name in {"params", "x0_m", "theta0_rad"}:  # state the handlers read: attributes of the session
            assert member is None and name in live.__dict__, name
            continue
        assert inspect.isfunction(member), f"LiveTwin has no command {name}"
        params = [p.name for p in inspect.signature(member).parameters.values()]
        assert params == [a.arg for a in declared.args.args], name


@pytest.mark.quick
def test_every_handler_reaches_the_session_only_through_its_commands() -> None:
    """Every attribute a handler (or a helper it calls) takes of the session is a member of ``Commands``,
    every action the GUI or the server enqueues has a handler, and the handlers' module does not import the
    session."""
    tree = ast.parse(Path(actions.__file__).read_text(encoding="utf-8"))
    commands = set(_commands())
    functions = [n for n in tree.body if isinstance(n, ast.FunctionDef)]
    taking_live = [f for f in functions if any(a.arg == "live" for a in f.args.args)]
    names = {f.name for f in taking_live}
    assert {h.__name__ for h in HANDLERS.values()} <= names  # every handler is read here
    for function in taking_live:
        reached = {
            n.attr
            for n in ast.walk(function)
            if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id == "live"
        }
        assert reached <= commands, f"{function.name} reaches LiveTwin.{sorted(reached - commands)}"
        passed_on = {  # the session passed whole only to another handler-side helper of this module
            n.func.id
            for n in ast.walk(function)
            if isinstance(n, ast.Call)
            and isinstance(n.func, ast.Name)
            and any(isinstance(a, ast.Name) and a.id == "live" for a in n.args)
        }
        assert passed_on <= names, function.name
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert "twin.viewer.session" not in imported
    enqueued: set[str] = set()
    for module in ("gui.py", "server.py"):
        for node in ast.walk(ast.parse((VIEWER / module).read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
                func = node.func
                if isinstance(func, ast.Attribute) and func.attr == "enqueue":
                    enqueued.add(node.args[0].value)
            if isinstance(node, ast.Call) and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant):
                if isinstance(node.args[0], ast.Attribute) and node.args[0].attr == "enqueue":
                    enqueued.add(node.args[1].value)  # functools.partial(live.enqueue, "reset")
    assert {"controller", "reset", "x0", "download", "connected"} <= enqueued  # the scan sees them
    assert enqueued <= set(HANDLERS)


def _state(live: LiveTwin) -> dict[str, Any]:
    return {
        "controller": live.controller_name,
        "runs": live.runs,
        "running": live.running,
        "start": (live.x0_m, live.theta0_rad, live.run_x0_m, live.run_theta0_rad),
        "speed": live.speed,
        "noise": (live.noise, live.rig.params.ball_sensor.noise_enabled),
        "drift": (live.drift_pct, live.rig.params.motor.resistance_ohm),
        "reference": (live.reference_x_m, live.setpoint_m),
        "flick": live.flick_m_s,
        "true": tuple(float(v) for v in live.rig.true_state()),
        "refused": live.refused,
        "error": live.error,
    }


@pytest.mark.quick
def test_a_command_called_directly_changes_the_state_as_its_handler_did() -> None:
    """The same sequence as GUI actions (through the handlers) and as direct commands: the same state and the
    same trajectory, bit for bit."""
    by_gui, direct = _live(), _live()
    steps: list[tuple[tuple[str, Any], Any]] = [
        (("initial", (0.05, -0.02)), lambda live: live.set_initial_state(0.05, -0.02)),
        (("speed", 2.0), lambda live: live.set_speed(2.0)),
        (("drift", 10.0), lambda live: live.set_drift(10.0)),
        (("reset", None), lambda live: live.reset()),
        (("noise", False), lambda live: live.set_noise(False)),
        (("reference", 0.05), lambda live: live.set_reference(0.05)),
        (("tick", None), None),
        (("flick_right", 0.2), lambda live: (live.set_flick_speed(0.2), live.flick(0.2))),
        (("flick", -0.1), lambda live: live.flick(-0.1)),
        (("tick", None), None),
        (("run", False), lambda live: live.set_running(False)),
        (("step", None), lambda live: live.step()),
        (("controller", "sf"), lambda live: live.set_controller("sf")),
        (("theta0", 0.05), lambda live: live.set_initial_state(live.x0_m, 0.05)),
        (("x0", -0.1), lambda live: live.set_initial_state(-0.1, live.theta0_rad)),
        (("run", True), lambda live: live.set_running(True)),
    ]
    changes: dict[str, dict[str, Any]] = {
        "initial": {"x0_m": 0.05, "theta0_rad": -0.02},
        "speed": {"speed": 2.0},
        "drift": {"drift_pct": 10.0},
        "reset": {"runs": 2, "run_x0_m": 0.05, "run_theta0_rad": -0.02},
        "noise": {"noise": False},
        "reference": {"reference_x_m": 0.05, "setpoint_m": 0.05},
        "flick_right": {"flick_m_s": 0.2},
        "step": {"running": False},
        "controller": {"controller_name": "sf", "runs": 3},
        "theta0": {"x0_m": 0.05, "theta0_rad": 0.05},
        "x0": {"x0_m": -0.1, "theta0_rad": 0.05},
    }
    for (action, value), command in steps:
        if action == "tick":
            for live in (by_gui, direct):
                for _ in range(5):
                    live.tick()
            continue
        xdot = {id(live): live.rig.true_state()[2] for live in (by_gui, direct)}
        by_gui.apply(action, value)
        command(direct)
        direct.apply_actions()  # the loop's next pass: a reset or a new controller starts its run here
        assert _state(direct) == _state(by_gui), action
        for live in (by_gui, direct):  # and the state did change as the action asks
            assert {k: getattr(live, k) for k in changes.get(action, {})} == changes.get(action, {}), action
            if action.startswith("flick"):  # a kick of the ball's speed along the beam
                kick = {"flick_right": 0.2, "flick": -0.1}[action]
                assert live.rig.true_state()[2] - xdot[id(live)] == pytest.approx(kick, abs=1e-9)
    for live in (by_gui, direct):
        for _ in range(10):
            live.tick()
    assert _state(direct) == _state(by_gui) and by_gui.refused == 0 and by_gui.runs == 3 and by_gui.running
    assert by_gui.controller_name == "sf" and by_gui.flick_m_s == 0.2 and by_gui.speed == 2.0
    np.testing.assert_array_equal(direct.loop.log().true_x_m, by_gui.loop.log().true_x_m)


@pytest.mark.quick
def test_a_command_refuses_what_the_sessions_state_refuses_and_changes_nothing() -> None:
    live = _live("appendix-clp")  # declares no setpoint
    before = _state(live)
    for command in (
        lambda: live.set_initial_state(10.0, 0.0),  # off the track
        lambda: live.set_initial_state(0.0, 3.0),  # beyond the stops
        lambda: live.set_reference(0.05),
        lambda: live.set_controller("no-such-controller"),
        lambda: live.set_shadow(True),  # this view has no shadow
    ):
        with pytest.raises(Refused):
            command()
    assert _state(live) == before
    # The same refusals through the GUI's handlers are recorded, the state unchanged as well.
    for action, value in (("reference", 0.05), ("controller", "no-such-controller"), ("shadow", True)):
        live.apply(action, value)
    assert live.refused == 3 and _state(live) == {**before, "refused": 3}
    commands: Commands = live  # the session is the handlers' Commands (mypy checks it structurally)
    assert commands is live
