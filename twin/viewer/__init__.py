"""Live browser view of the twin (viser): the rig in 3D at 50 Hz, controls, and live plots.

One room per concern: ``session`` (the simulation loop's state: it owns the twin and the controller, and offers
typed commands; GUI callbacks only enqueue actions, which the loop applies between ticks, a burst coalesced),
``actions`` (the GUI's handlers: a control's value checked, then a command of the session), ``security`` (who
may connect and what a client's messages can reach: the only room touching viser's internals), ``scene`` (the
3D nodes), ``channels`` (what the plots show of the rig's board and parts, in its units, and the ranging
sensor's beam), ``gui`` (panels, plots, notifications), ``server`` (the viser server, the pacing loop, ``serve``)
and ``common`` (the controls' ranges, constants, one-line logs).

Nothing a client sends is trusted: a foreign ``Origin`` or ``Host`` is refused at the handshake, a message
that is not a plain value of a known control is dropped, and every value is checked by the loop against the
controls' ranges and the current parameters and refused (notification, status line, one log line) with the
state unchanged. A controller or rig that fails marks the run failed; nothing a client sends stops the server.
"""

from twin.viewer.common import (
    _WS_LOGGER,
    DEFAULT_CONTROLLER,
    FLICK,
    FLICK_DEFAULT_M_S,
    FRAME_S,
    MAX_OWED_S,
    SETPOINT,
    SPEED,
    SPEED_MAX,
    SPEED_MIN,
    THETA0,
    X0,
    Slider,
    ViewerError,
    _log_last,
)
from twin.viewer.gui import PLOT_AXIS_PX, PLOTS, parameter_changes, uplot_data
from twin.viewer.scene import CAMERAS, build_scene
from twin.viewer.security import MAX_MESSAGE_BYTES, OriginPolicy, is_loopback
from twin.viewer.server import Viewer, serve
from twin.viewer.session import (
    MAX_PENDING_ACTIONS,
    RECORD_LIMIT_S,
    History,
    LiveTwin,
    Refusal,
    owe,
    verdict_text,
)

__all__ = [
    "CAMERAS",
    "DEFAULT_CONTROLLER",
    "FLICK",
    "FLICK_DEFAULT_M_S",
    "FRAME_S",
    "MAX_MESSAGE_BYTES",
    "MAX_OWED_S",
    "MAX_PENDING_ACTIONS",
    "PLOTS",
    "PLOT_AXIS_PX",
    "RECORD_LIMIT_S",
    "SETPOINT",
    "SPEED",
    "SPEED_MAX",
    "SPEED_MIN",
    "THETA0",
    "X0",
    "History",
    "LiveTwin",
    "OriginPolicy",
    "Refusal",
    "Slider",
    "Viewer",
    "ViewerError",
    "_WS_LOGGER",
    "_log_last",
    "build_scene",
    "is_loopback",
    "owe",
    "parameter_changes",
    "serve",
    "uplot_data",
    "verdict_text",
]
