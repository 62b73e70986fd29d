"""The shadow: the twin following a running rig window by window, with a drift alarm.

While a rig runs (on the wire: ``twin.serving.observer.Observer`` reads its samples and the commands it applies), the
stream is cut into the windows ``calib.compare`` cuts a log into (1 s), and each window, once complete, is
*predicted* as compare predicts it: its start state is the end of the previous window's state fitted to that
window's readings, and the model (at the shadow's parameters) runs the window's applied commands for the first
0.5 s. No reading of the predicted span entered the prediction, so its error is the model's plus what the
estimate carries — and the estimate's share does not depend on what the controller does (for a model that is
right, the error of a linear system's prediction is the estimate's error propagated, whatever the input),
while a wrong model's grows with the input it mispredicts (a motor 15 % weaker errs in proportion to the
volts it is driven with).

**The drift test.** Each predicted window gives, per channel (ball, angle), the log of its RMS error. Its
in-control distribution, the **band**, is measured on windows known to be right (``Band``): the twin's own
runs at the shadow's parameters (``twin.app.shadow.reference_band``) or logs the user recorded on the rig
when it was known good. A window's score is its standardized error z = (log RMS − mean)/sd, and a one-sided
CUSUM per channel, S ← max(0, S + z − k), raises the **drift alarm** when S > h (``Cusum``: k = 1, h = 7,
the reference value half-way to a 2-sd shift). Its false-alarm rate is stated two ways: the average run
length of the in-control CUSUM by Siegmund's approximation for normal scores, and the probability of an
alarm within an hour of windows, by resampling the band's own scores (both channels together: an alarm on
either is an alarm). After an alarm the channel's sum restarts at zero; the alarm stays raised
(``Shadow.alarmed``) — a drift is for the operator to acknowledge, not for the test to forget.

Windows that are not the model's to predict are not scored and leave the sums as they are: the rig held or
the ball lost (the samples' flags), the watchdog's zero command, a sample or an applied command the shadow
did not receive, and what calibration's screen leaves out (a stretch at the amplifier's rails).

The shadow never writes to the rig: it reads.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.compare import CHANNELS, DEFAULT_HORIZON_S, LogWindows, WindowedPrediction, windowed_prediction
from calib.identify import CalibrationError
from calib.logs import RigLog
from twin.log import LogError
from twin.parameters import Parameters

__all__ = [
    "FLAGS_NOT_SCORED",
    "MIN_BAND_WINDOWS",
    "Alarm",
    "Band",
    "Cusum",
    "Shadow",
    "WindowScore",
]

# Samples whose window is not scored (docs/protocol.md's SAMPLE flags): held (bit 0), ball lost (bit 1),
# watchdog (bit 2: the output is the zero command, not the controller's).
FLAGS_NOT_SCORED = 0b111
# A band from fewer windows would state a false-alarm rate its own sampling error swamps.
MIN_BAND_WINDOWS = 30
# At most this many windows in one state fit: a backlog (a lock-step session outruns the shadow) is worked
# off in batches whose cost is mostly fixed per fit.
MAX_BATCH_WINDOWS = 30
# Siegmund's correction of the CUSUM threshold for the overshoot of a normal random walk (h + 1.166).
_SIEGMUND_OVERSHOOT = 1.166


@dataclass(frozen=True)
class Band:
    """The in-control distribution of a predicted window's log RMS error, per channel, and the reference
    windows' standardized scores (for the false-alarm rate by resampling)."""

    mean: dict[str, float]  # of ln(RMS), the RMS in metres (ball) and radians (angle)
    sd: dict[str, float]
    z: np.ndarray  # (windows, 2): the reference windows' scores, ball and angle together
    source: str

    @property
    def windows(self) -> int:
        return int(self.z.shape[0])

    @classmethod
    def from_predictions(cls, predictions: Sequence[WindowedPrediction], source: str) -> Band:
        """The band of the predicted windows of ``predictions`` (windows a right model predicted)."""
        rows = [_log_rms(wp) for wp in predictions]
        x = np.concatenate(rows) if rows else np.zeros((0, 2))
        if x.shape[0] < MIN_BAND_WINDOWS:
            raise CalibrationError(
                f"{source}: {x.shape[0]} predicted windows, the band needs at least {MIN_BAND_WINDOWS} "
                "(longer reference logs)"
            )
        mean, sd = x.mean(axis=0), x.std(axis=0, ddof=1)
        if not np.all(sd > 0):
            raise CalibrationError(f"{source}: the reference windows' errors do not vary: no band")
        return cls(
            mean=dict(zip(CHANNELS, mean.tolist(), strict=True)),
            sd=dict(zip(CHANNELS, sd.tolist(), strict=True)),
            z=(x - mean) / sd,
            source=source,
        )

    def score(self, rms: dict[str, float]) -> dict[str, float]:
        """A window's standardized scores: (ln RMS − mean)/sd per channel."""
        return {c: (math.log(rms[c]) - self.mean[c]) / self.sd[c] for c in CHANNELS}

    def to_json(self) -> dict[str, object]:
        return {
            "source": self.source,
            "windows": self.windows,
            "ln_rms_mean": self.mean,
            "ln_rms_sd": self.sd,
            "rms_median": {c: math.exp(self.mean[c]) for c in CHANNELS},
        }


def _log_rms(wp: WindowedPrediction) -> np.ndarray:
    """ln(RMS) of every predicted window of ``wp`` whose both channels were scored, (windows, 2)."""
    out = []
    for lw in wp.logs:
        rms = wp.window_rms(lw)
        both = np.stack([rms[c] for c in CHANNELS], axis=1)
        keep = lw.joined & np.all(np.isfinite(both) & (both > 0), axis=1)
        out.append(np.log(both[keep]))
    return np.concatenate(out) if out else np.zeros((0, 2))


@dataclass(frozen=True)
class Cusum:
    """A one-sided CUSUM per channel on standardized scores: S ← max(0, S + z − k), alarm when S > h."""

    k: float = 1.0  # reference value: half the 2-sd shift it is tuned to detect fastest
    h: float = 7.0  # decision threshold: see the module's docstring for its false-alarm rate

    def update(self, s: float, z: float) -> float:
        return max(0.0, s + z - self.k)

    def run_length_normal(self, shift: float = 0.0) -> float:
        """Siegmund's approximation of the average number of windows to an alarm of one channel whose scores
        are normal with mean ``shift`` (0: in control, the average run length to a false alarm)."""
        b = self.h + _SIEGMUND_OVERSHOOT
        d = shift - self.k
        if abs(d) < 1e-9:
            return b * b
        return (math.exp(-2.0 * d * b) + 2.0 * d * b - 1.0) / (2.0 * d * d)

    def false_alarm_probability(
        self, band: Band, windows: int, *, chains: int = 4000, seed: int = 0
    ) -> float:
        """The probability of an alarm (either channel) within ``windows`` in-control windows, by running
        ``chains`` CUSUMs over the band's own scores resampled (each window's two channels kept together,
        so their correlation and the scores' real tails are the reference's)."""
        rng = np.random.default_rng(seed)
        s = np.zeros((chains, 2))
        alarmed = np.zeros(chains, dtype=bool)
        for _ in range(windows):
            z = band.z[rng.integers(0, band.windows, size=chains)]
            s = np.maximum(0.0, s + z - self.k)
            alarmed |= np.any(s > self.h, axis=1)
        return float(np.mean(alarmed))

    def to_json(self) -> dict[str, float]:
        return {
            "k": self.k,
            "h": self.h,
            "in_control_run_length_windows": round(self.run_length_normal(0.0), 1),
            "run_length_2sd_windows": round(self.run_length_normal(2.0), 2),
        }


@dataclass(frozen=True)
class Alarm:
    """The drift alarm of one channel: the CUSUM crossed h at the end of window ``window``."""

    channel: str
    window: int
    time_s: float  # rig time of the window's last tick
    cusum: float

    def to_json(self) -> dict[str, object]:
        return {
            "channel": self.channel,
            "window": self.window,
            "time_s": round(self.time_s, 4),
            "cusum": self.cusum,
        }


@dataclass
class WindowScore:
    """One window of the stream: its prediction's error and the test's state after it (or why not scored)."""

    window: int
    start_s: float
    end_s: float
    skipped: str = ""  # why the window was not scored ("" when it was)
    rms: dict[str, float] = field(default_factory=dict)
    z: dict[str, float] = field(default_factory=dict)
    cusum: dict[str, float] = field(default_factory=dict)
    alarms: list[Alarm] = field(default_factory=list)
    # The predicted span, for plots: rig time, readings (m, rad) and the model's prediction of them.
    t_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured: dict[str, np.ndarray] = field(default_factory=dict)
    predicted: dict[str, np.ndarray] = field(default_factory=dict)

    def to_json(self) -> dict[str, object]:
        out: dict[str, object] = {
            "window": self.window,
            "start_s": round(self.start_s, 4),
            "end_s": round(self.end_s, 4),
        }
        if self.skipped:
            out["skipped"] = self.skipped
        else:
            out["rms"] = {c: self.rms[c] for c in CHANNELS}
            out["z"] = {c: round(self.z[c], 4) for c in CHANNELS}
        out["cusum"] = {c: round(v, 4) for c, v in self.cusum.items()}
        if self.alarms:
            out["alarms"] = [a.to_json() for a in self.alarms]
        return out


class Shadow:
    """The stream of one rig (``add`` every sample with the DAC volts of its block), its windows predicted
    (``process``) and tested against ``band`` by ``test``.

    Window n holds the samples seq 3 + n·W … 2 + (n + 1)·W of a session (W ticks of ``window_s``), the
    windows ``calib.compare`` cuts the session's log into (its row 1 is the held block, seq 0); window 0 has
    no predecessor, so the first scored is window 1. The sums carry over from one session to the next
    (the rig is the same); ``new_session`` forgets the stream."""

    def __init__(
        self,
        params: Parameters,
        band: Band,
        test: Cusum | None = None,
        *,
        window_s: float = 1.0,
        horizon_s: float = DEFAULT_HORIZON_S,
    ) -> None:
        self.params = params
        self.band = band
        self.test = test or Cusum()
        self.period_s = float(params.period_s)
        self.W = max(2, int(round(window_s / self.period_s)))
        self.window_s = self.W * self.period_s
        self.horizon_s = horizon_s
        self.cusum = {c: 0.0 for c in CHANNELS}
        self.alarms: list[Alarm] = []
        self.scored = 0
        self.skipped = 0
        self.session = 0
        self._reset_stream()

    @property
    def alarmed(self) -> bool:
        """Whether a drift alarm has been raised (latched)."""
        return bool(self.alarms)

    @property
    def threshold(self) -> float:
        """The sums' alarm threshold h."""
        return self.test.h

    def _reset_stream(self) -> None:
        self._first = 0  # the seq of the arrays' first element
        self._time: list[float] = []
        self._ball: list[float] = []
        self._angle: list[float] = []
        self._flags: list[int] = []
        self._dac: list[float] = []  # the DAC volts during the block (NaN: not known)
        self._next = 1  # the next window to score

    def new_session(self) -> None:
        """A new session of the rig: its seq starts again at 0."""
        self.session += 1
        self._reset_stream()

    def add(self, seq: int, time_s: float, ball_v: float, angle_v: float, flags: int, dac_v: float) -> None:
        """SAMPLE ``seq`` (its flags), with the DAC volts held during its block (NaN if not known). A seq
        beyond the next leaves the samples between missing; an earlier one (a repeat) is ignored."""
        i = seq - self._first
        if i < len(self._time):
            return
        while len(self._time) < i:  # lost samples: a hole no window across it is scored over
            for arr in (self._time, self._ball, self._angle, self._dac):
                arr.append(math.nan)
            self._flags.append(-1)
        self._time.append(time_s)
        self._ball.append(ball_v)
        self._angle.append(angle_v)
        self._flags.append(flags)
        self._dac.append(dac_v)

    def pending(self) -> int:
        """Complete windows not yet processed."""
        last_seq = self._first + len(self._time) - 1
        complete = (last_seq - 2) // self.W  # window n ends at seq 2 + (n + 1)·W
        return max(0, complete - self._next)

    def _span(self, n: int) -> range:
        """The array indices of window n's samples."""
        a = 3 + n * self.W - self._first
        return range(a, a + self.W)

    def _why_not(self, n: int) -> str:
        """Why window n cannot be scored from window n − 1 ("" if it can): what its samples say."""
        lo, hi = self._span(n - 1).start - 2, self._span(n).stop  # and the two samples before (start guess)
        flags = self._flags[max(0, lo) : hi]
        if lo < 0 or any(f < 0 for f in flags):
            return "samples missing"
        if any(f & 0b001 for f in flags):
            return "rig held"
        if any(f & 0b010 for f in flags):
            return "ball lost"
        if any(f & 0b100 for f in flags):
            return "watchdog"
        if not all(math.isfinite(v) for v in self._dac[lo:hi]):
            return "applied command not received"
        return ""

    def process(self, max_windows: int = MAX_BATCH_WINDOWS) -> list[WindowScore]:
        """Predict and test the complete windows not yet processed (at most ``max_windows``), in order."""
        out: list[WindowScore] = []
        todo = list(range(self._next, self._next + min(self.pending(), max_windows)))
        run: list[int] = []
        reasons = {n: self._why_not(n) for n in todo}
        for n in todo:
            if reasons[n]:
                if run:
                    out += self._predict_run(run)
                    run = []
                out.append(self._skip(n, reasons[n]))
            else:
                run.append(n)
        if run:
            out += self._predict_run(run)
        if todo:
            self._next = todo[-1] + 1
            self._trim()
        return out

    def _bounds(self, n: int) -> tuple[float, float]:
        span = self._span(n)
        return self._time[span.start], self._time[span.stop - 1]

    def _skip(self, n: int, reason: str) -> WindowScore:
        self.skipped += 1
        start, end = self._bounds(n)
        return WindowScore(n, start, end, skipped=reason, cusum=dict(self.cusum))

    def _predict_run(self, windows: list[int]) -> list[WindowScore]:
        """Windows n0…n1, each predictable from the one before: one state fit over n0 − 1 … n1."""
        n0, n1 = windows[0], windows[-1]
        a = self._span(n0 - 1).start - 2  # the RigLog's element 0: window n0 − 1 starts at its element 2
        b = self._span(n1).stop  # one past the last sample
        seg = slice(a, b)
        # A RigLog's command at a tick is the one written then: the DAC of the next block. The segment's last
        # one acts beyond it (never simulated; it may not have come, or be lost): its predecessor stands in.
        command = np.array(self._dac[a + 1 : b] + self._dac[b - 1 : b])
        try:
            log = RigLog(
                path=Path(f"session {self.session}"),
                time_s=np.array(self._time[seg]),
                ball_v=np.array(self._ball[seg]),
                angle_v=np.array(self._angle[seg]),
                command_v=command,
                whole=False,
            )
            wp = windowed_prediction([log], self.params, window_s=self.window_s, horizon_s=self.horizon_s)
        except (LogError, CalibrationError) as exc:  # what a rig sent is not a log (times not increasing, …)
            reason = str(exc).partition(": ")[2] or str(exc)
            return [self._skip(n, reason) for n in windows]
        lw = wp.logs[0]
        rms = wp.window_rms(lw)
        by_start = {round(float(t), 9): m for m, t in enumerate(lw.t_s[:, 0])}
        out = []
        for n in windows:
            start, end = self._bounds(n)
            m = by_start.get(round(start, 9))
            if m is None or not lw.joined[m]:
                # Calibration's screen left it or its predecessor out: a stretch at the rails, or the ball lost.
                why = {round(d.start_s, 9): d.reason for d in lw.dropped}
                reason = why.get(round(start, 9)) or "previous window " + why.get(
                    round(self._bounds(n - 1)[0], 9), "left out"
                )
                out.append(self._skip(n, reason))
                continue
            r = {c: float(rms[c][m]) for c in CHANNELS}
            if not all(math.isfinite(v) and v > 0 for v in r.values()):
                out.append(self._skip(n, "prediction diverged"))
                continue
            out.append(self._score(n, start, end, r, lw, m))
        return out

    def _score(
        self, n: int, start: float, end: float, rms: dict[str, float], lw: LogWindows, m: int
    ) -> WindowScore:
        z = self.band.score(rms)
        alarms = []
        for c in CHANNELS:
            self.cusum[c] = self.test.update(self.cusum[c], z[c])
            if self.cusum[c] > self.test.h:
                alarms.append(Alarm(c, n, end, self.cusum[c]))
                self.cusum[c] = 0.0
        self.alarms += alarms
        self.scored += 1
        h = lw.horizon
        return WindowScore(
            n,
            start,
            end,
            rms=rms,
            z=z,
            cusum=dict(self.cusum),
            alarms=alarms,
            t_s=lw.t_s[m, :h].copy(),
            measured={c: lw.measured[c][m, :h].copy() for c in CHANNELS},
            predicted={c: lw.predicted[c][m, :h].copy() for c in CHANNELS},
        )

    def _trim(self) -> None:
        """Forget the samples no window still to come needs (the stream of an hour stays a few windows)."""
        keep_from = self._span(self._next - 1).start - 2
        if keep_from > 0:
            for arr in (self._time, self._ball, self._angle, self._flags, self._dac):
                del arr[:keep_from]
            self._first += keep_from

    def summary(self) -> dict[str, object]:
        return {
            "scored_windows": self.scored,
            "skipped_windows": self.skipped,
            "alarmed": self.alarmed,
            "alarms": [a.to_json() for a in self.alarms],
            "cusum": dict(self.cusum),
        }
