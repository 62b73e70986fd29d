"""The live view's session and panels: controls' ranges enforced as the sliders define them, bursts of
actions coalesced, downloads built once per record state, NaN plot series drawn as gaps, the setpoint as a
declared capability, and a verdict so far that calls the release's transient a transient."""

from __future__ import annotations

import math
import socket
import time
from typing import Any

import numpy as np
import pytest
import viser
from viewer_stubs import StubCatalogue

from twin import converters
from twin.app.plots import run_figure
from twin.engine import CatalogueEntry
from twin.interface import Controller, DaqSample
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop
from twin.verdict import Criteria
from twin.viewer import FLICK, SETPOINT, THETA0, X0, LiveTwin, uplot_data, verdict_text
from twin.viewer.security import send_uplot_data


class NoEstimate(Controller):
    """A user's controller that logs no estimate (its telemetry stays NaN): a constant mid-scale command."""

    name = "no-estimate"

    def start(self, sample: DaqSample) -> None:
        pass

    def update(self, sample: DaqSample) -> float:
        return 2.5


class Settable(Controller):
    """Declares twin.interface.Setpoint with a plain attribute; holds the motor still."""

    name = "settable"

    def __init__(self) -> None:
        super().__init__()
        self.setpoint_m = 0.0

    def start(self, sample: DaqSample) -> None:
        pass

    def update(self, sample: DaqSample) -> float:
        return 2.5


def _live(controller: str = "lqr", catalogue: Any = None, **kwargs: Any) -> LiveTwin:
    return LiveTwin(Parameters(), catalogue or StubCatalogue(), controller, 0, 1.0, **kwargs)


def _state(live: LiveTwin) -> tuple:
    return (live.x0_m, live.theta0_rad, live.reference_x_m, live.runs, live.flick_m_s)


# --- ranges -----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("action", "value", "slider"),
    [
        ("x0", X0.high + 0.01, X0),  # 0.31 m
        ("x0", X0.low - 0.01, X0),
        ("theta0", THETA0.high + 0.05, THETA0),  # 0.75 rad
        ("reference", SETPOINT.high + 0.1, SETPOINT),  # 0.3 m
        ("flick_right", -0.3, FLICK),  # a negative speed: it would flick the other way
        ("flick_left", -0.3, FLICK),
        ("flick_right", FLICK.high + 0.01, FLICK),
        ("flick_left", 0.0, FLICK),
        ("flick", FLICK.high + 0.1, FLICK),
    ],
)
def test_a_value_outside_its_slider_is_refused(action: str, value: float, slider: Any) -> None:
    """Inside the track (±0.35 m) and the stops (±0.757 rad), outside the slider: refused, state kept."""
    p = Parameters()
    assert abs(value) <= max(p.track.half_length_m, p.beam.stop_angle_rad)  # only the slider refuses it
    live = _live()
    live.tick()
    before, ball = _state(live), live.rig.true_state().copy()
    live.apply(action, value)
    assert live.refused == 1
    reason = live.refusals[-1].reason
    assert "outside" in reason and f"{slider.high:g}" in reason
    assert _state(live) == before
    np.testing.assert_array_equal(live.rig.true_state(), ball)  # no flick either way


@pytest.mark.parametrize(("action", "sign"), [("flick_left", -1.0), ("flick_right", 1.0)])
def test_a_flick_goes_the_way_of_its_button_at_the_sliders_speed(action: str, sign: float) -> None:
    live = _live()
    live.tick()
    xdot = float(live.rig.true_state()[2])
    live.apply(action, 0.3)
    assert live.refused == 0 and live.flick_m_s == 0.3
    assert float(live.rig.true_state()[2]) - xdot == pytest.approx(sign * 0.3, abs=1e-9)


# --- bursts -----------------------------------------------------------------------------------------------
def _5000_queued_resets() -> tuple[float, float]:
    """5000 resets queued and applied in one frame, which leaves one fresh run: the seconds that took, and the
    seconds one more reset takes."""
    live = _live("appendix-clp")
    for _ in range(10):
        live.tick()
    runs = live.runs
    for _ in range(5000):
        live.enqueue("reset")
    assert live.pending_actions == 1  # the latest wins while it waits
    start = time.perf_counter()
    live.apply_actions()
    elapsed = time.perf_counter() - start
    assert live.pending_actions == 0 and live.runs == runs + 1 and live.rig.time_s < 0.0  # held, fresh
    build = time.perf_counter()
    live.apply("reset")
    return elapsed, time.perf_counter() - build


@pytest.mark.quick
def test_5000_queued_resets_are_one_run_applied_in_one_frame() -> None:
    _5000_queued_resets()  # what it costs: below


@pytest.mark.realtime
def test_5000_queued_resets_cost_about_one_runs_start() -> None:
    """A ratio of two wall-clock durations: a realtime test."""
    elapsed, one_run_s = _5000_queued_resets()
    assert elapsed < 3 * one_run_s + 0.05  # the burst costs about one run's start, not 5000


def test_a_burst_of_run_starts_starts_the_last_once_and_keeps_the_order() -> None:
    live = _live("appendix-clp")
    runs = live.runs
    for action, value in [
        ("reset", None),
        ("controller", "lqr"),
        ("reset", None),
        ("x0", 0.2),
        ("reset", None),
    ]:
        live.enqueue(action, value)
    live.apply_actions()
    # reset, lqr, reset: one start of lqr (at the old x0); then x0 = 0.2 and its reset: a second start
    assert live.runs == runs + 2 and live.controller_name == "lqr"
    assert float(live.rig.true_state()[0]) == 0.2 and live.run_x0_m == 0.2


def test_a_controller_that_cannot_start_in_a_burst_is_refused_once() -> None:
    def broken(params: Parameters | None) -> Controller:
        raise RuntimeError("cannot build")

    live = _live("appendix-clp", StubCatalogue({"broken": broken}))
    runs = live.runs
    live.enqueue("reset")
    live.enqueue("controller", "broken")
    live.apply_actions()
    assert live.refused == 1 and "cannot build" in live.refusals[-1].reason
    assert live.refusals[-1].action == "controller"
    assert live.runs == runs and live.controller_name == "appendix-clp"


# --- downloads --------------------------------------------------------------------------------------------
def test_250_downloads_of_a_full_record_build_one_file(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("twin.viewer.session.RECORD_LIMIT_S", 1.0)
    live = _live("appendix-clp")
    while live.loop.recording:
        live.tick()
    for _ in range(5):
        live.tick()  # the run goes on; the record is full
    received: list[bytes] = []
    for _ in range(250):
        live.apply("download", ("mat", lambda name, data: received.append(data)))
    assert len(received) == 250 and live.downloads_built == 1
    assert all(data is received[0] for data in received)  # one file held, whatever the clicks
    assert len(received[0]) > 1000
    live.apply("download", ("csv", lambda name, data: received.append(data)))
    live.apply("reset")
    live.tick()
    live.apply("download", ("mat", lambda name, data: received.append(data)))
    assert live.downloads_built == 3  # a new format, a new record: built again
    assert received[-1] != received[0]


# --- plots ------------------------------------------------------------------------------------------------
@pytest.mark.quick
def test_a_nan_series_is_a_gap_and_the_rest_of_the_chart_stays() -> None:
    live = _live("no-estimate", StubCatalogue({"no-estimate": lambda params: NoEstimate()}))
    for _ in range(10):
        live.tick()
    h = live.history
    t = h.array("t")
    data = uplot_data(t, [h.array(key) for key in ("x_true", "x_meas", "x_est", "x_ref")])
    assert data[0] is t and len(data) == 5
    x_true, x_meas, x_est, x_ref = data[1:]
    assert isinstance(x_true, np.ndarray) and np.isfinite(x_true).all() and x_true.size == t.size
    assert isinstance(x_meas, np.ndarray) and np.isfinite(x_meas).all()
    assert x_est == [None] * t.size  # no estimate: a gap over the whole series
    partial = uplot_data(t[:3], [np.array([1.0, np.nan, 3.0], dtype=np.float32)])
    assert partial[1] == [1.0, None, 3.0]


@pytest.mark.quick
def test_the_chart_data_sent_to_the_browser_keeps_the_gap() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    try:
        series = (viser.uplot.Series(label="t"), viser.uplot.Series(label="a"), viser.uplot.Series(label="b"))
        handle = server.gui.add_uplot(tuple(np.zeros(2) for _ in series), series)
        t = np.array([0.0, 0.02, 0.04])
        send_uplot_data(handle, uplot_data(t, [np.array([1.0, 2.0, 3.0]), np.full(3, np.nan)]))
        buffer = server._websock_server.get_message_buffer()
        sent = [
            m.updates["data"]
            for m in buffer.message_from_id.values()
            if type(m).__name__ == "GuiUpdateMessage" and "data" in m.updates
        ]
        assert sent, "no chart update was queued"
        columns = sent[-1]
        assert columns[2] == [None, None, None]  # msgpack nil: uPlot's gap
        np.testing.assert_array_equal(columns[1], [1.0, 2.0, 3.0])
        assert np.isnan(handle.data[2]).all() and handle.data[1][2] == 3.0
    finally:
        server.stop()


@pytest.mark.quick
@pytest.mark.parametrize("controller", ["no-estimate", "thesis-sf"])
def test_the_run_plot_draws_the_measured_trace_for_any_controller(controller: str) -> None:
    from controllers import registry

    params = Parameters()
    built = NoEstimate() if controller == "no-estimate" else registry.make(controller, params)
    result = run_closed_loop(built, x0_m=0.1, theta0_rad=0.0, duration_s=1.0, seed=0)
    fig = run_figure(result, software=params.software)
    try:
        lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
        measured = next(line for label, line in lines.items() if label.startswith("measured"))
        y = np.asarray(measured.get_ydata(), dtype=float)
        log = result.log
        assert y.size == log.timem.size and np.isfinite(y).all()
        np.testing.assert_array_equal(y, converters.ball_position_m(log.datam1, params.software))
        assert ("estimate" in lines) == (controller == "thesis-sf")  # drawn only where one was logged
        theta = next(line for line in fig.axes[1].get_lines() if line.get_label().startswith("measured"))
        assert np.isfinite(np.asarray(theta.get_ydata(), dtype=float)).all()
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


# --- setpoint ---------------------------------------------------------------------------------------------
@pytest.mark.quick
def test_the_setpoint_is_the_declared_capability() -> None:
    catalogue = StubCatalogue({"settable": lambda params: Settable()}, setpoint=("settable",))
    live = _live("settable", catalogue)
    assert live.supports_reference
    live.apply("reference", 0.1)
    assert live.controller.setpoint_m == 0.1 and live.setpoint_m == 0.1
    live.apply("reset")
    assert live.controller.setpoint_m == 0.1  # a new run gets the setpoint too


def test_a_controller_the_catalogue_says_has_no_setpoint_is_left_alone() -> None:
    catalogue = StubCatalogue({"settable": lambda params: Settable()})
    assert catalogue.ENTRIES["settable"] == CatalogueEntry(
        "settable", catalogue.ENTRIES["settable"].build, "settable", False, False, setpoint=False
    )
    live = _live("settable", catalogue)
    assert not live.supports_reference and "declares no setpoint" in live.setpoint_reason
    live.apply("reference", 0.1)
    assert live.controller.setpoint_m == 0.0 and live.setpoint_m == 0.0  # remembered, not applied
    live = _live("no-estimate", StubCatalogue({"no-estimate": lambda params: NoEstimate()}))
    assert not live.supports_reference


# --- the verdict so far -----------------------------------------------------------------------------------
def test_the_verdict_so_far_calls_the_transient_a_transient() -> None:
    """appendix-clp from the default start: 4 s after release the final 3 s window still holds the release's
    transient (tens of mm p-p, not settled): 'transient'; from 2 windows on, the verdict; once settled, held."""
    c = Criteria()
    live = _live("appendix-clp")
    while live.rig.time_s < 4.0:
        live.tick()
    v = live.loop.verdict(live.run_x0_m)
    assert v.limit_cycle_x_pp_m is not None and v.limit_cycle_x_pp_m > c.limit_cycle_band_m
    assert v.settling_time_s is None
    text = verdict_text(v)
    assert "transient" in text and "cycle" not in text and "not held" not in text
    assert "transient" in live.status_markdown()
    while live.rig.time_s < 2 * c.window_s:
        live.tick()
    assert "transient" not in verdict_text(live.loop.verdict(live.run_x0_m))
    while live.rig.time_s < 9.0:
        live.tick()
    v = live.loop.verdict(live.run_x0_m)
    assert v.held and v.settling_time_s is not None and verdict_text(v).startswith("verdict so far: held")
    assert math.isfinite(v.steady_x_m or math.nan)


@pytest.mark.quick
def test_the_three_cameras_look_at_the_rig_from_under_a_metre() -> None:
    """The view's cameras (twin.viewer.scene), as the README lists them: three-quarter, side, top; each looks
    at the beam's pivot (on the rig's axis, a quarter metre up) from another point, with a unit up vector."""
    from twin.viewer.scene import CAMERAS

    assert list(CAMERAS) == ["Three-quarter", "Side", "Top"]
    for position, look_at, up in CAMERAS.values():
        distance = float(np.linalg.norm(np.subtract(position, look_at)))
        assert look_at[:2] == (0.0, 0.0) and 0.2 < look_at[2] < 0.3
        assert 0.5 < distance < 1.0 and float(np.linalg.norm(up)) == 1.0


@pytest.mark.quick
def test_an_estimate_is_dashed_so_the_measurement_beneath_it_shows() -> None:
    """appendix-clp's estimated x is its reading: drawn solid over the measured trace it hid it."""
    from twin.viewer.gui import PLOTS, _series

    for _, traces in PLOTS:
        for name, _key, colour in traces:
            series = _series(name, colour)
            assert series["stroke"] == colour
            assert ("dash" in series) == (name == "estimated"), name
    assert any({"measured", "estimated"} <= {n for n, _k, _c in traces} for _, traces in PLOTS)
