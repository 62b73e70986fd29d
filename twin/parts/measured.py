"""What a rig's recorded log means, from its parts: the software conversions that turn a rig of other parts'
board readings and commands into the ball's x, the beam's θ and the actuator's control, for a verdict judged
from a log (``twin.verdict.evaluate_measured``: ``ballbeam judge``). The thesis's rig keeps its own (eq 6.3.1,
eq 6.2.10, the output stage), so there is none for it."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from twin.parameters import Parameters
from twin.parts.contract import PartError, rig_parts
from twin.parts.thesis import is_thesis_rig
from twin.verdict import MeasuredChannels

__all__ = ["measured_channels"]


def _each(f: Callable[[float], float]) -> Callable[[np.ndarray], np.ndarray]:
    return lambda values: np.array([f(float(v)) for v in np.asarray(values, dtype=float)], dtype=float)


def measured_channels(params: Parameters) -> MeasuredChannels | None:
    """The conversions of the rig ``params.parts`` names (None for the thesis's rig). A part that gives no
    conversion is refused naming it (``PartError``): its log cannot be judged."""
    parts = rig_parts(params)
    if is_thesis_rig(parts):
        return None
    ball, angle, actuator = parts.ball_sensor, parts.angle_sensor, parts.actuator
    missing = [
        f"parts.{part.role} = {part.name!r} ({what})"
        for part, what in (
            (ball, ball.position_of),
            (actuator, actuator.control_of),
            *(((angle, angle.angle_of),) if angle.measures_angle else ()),
        )
        if what is None
    ]
    if missing:
        raise PartError(
            f"a log of this rig cannot be judged: these parts give no conversion: {', '.join(missing)}"
        )
    assert ball.position_of is not None and actuator.control_of is not None
    angle_of = angle.angle_of(params) if angle.measures_angle and angle.angle_of is not None else None
    control_of = actuator.control_of(params)
    limits = parts.io_board.output_range(params)
    return MeasuredChannels(
        x_m=_each(ball.position_of(params)),
        theta_rad=None if angle_of is None else _each(angle_of),
        control=_each(control_of),
        control_limit=max(abs(control_of(limits.low)), abs(control_of(limits.high))),
        angle_step_rad=0.0 if angle_of is None else abs(angle_of(1.0) - angle_of(0.0)),
    )
