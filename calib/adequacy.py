"""Is the fitted model adequate? Residuals against the noise floor, and their whiteness, per channel.

A right model leaves residuals that are the sensors' noise: about the size of the channel's floor and
uncorrelated from tick to tick. A model that misses an effect (pivot friction the fit does not include)
leaves residuals far above the floor and correlated over many ticks, because the missing force acts through
the dynamics. Both are measured per channel, within the fit's windows (each window's state is fitted, so a
window boundary is not a lag):

* the floor is the channel's nominal noise from its sensor chain (``calib.identify.SIGMA_BALL_M``: the ADC's
  0.17 mm step and the curve's sub-millimetre error; ``SIGMA_ANGLE_RAD``: one encoder count, 3.5 mrad,
  as a uniform quantization's standard deviation, the worst case of a still beam); the ball channel's
  contact-noise outliers (more than ``OUTLIER_M`` off the model) are left out of its RMS and correlation;
* the normalized autocorrelation ρ(L) for lags 1…``MAX_LAG``, summed over windows, against the white-noise
  band ±1.96/√N.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["MAX_LAG", "ChannelAdequacy", "autocorrelation", "channel_adequacy"]

MAX_LAG = 5


def autocorrelation(segments: Sequence[np.ndarray], max_lag: int) -> np.ndarray:
    """The normalized autocorrelation of a residual made of separate segments (the windows), lags 0…max_lag:
    r(τ) = Σ e(t)·e(t+τ) / Σ e(t)², the products taken within each segment only (a window's end and the
    next window's start are not neighbours in a prediction). The residual is not de-meaned: a bias is part of
    the error and shows as correlation at every lag. White noise of N samples lies within ±1.96/√N."""
    total = sum(float(np.dot(s, s)) for s in segments)
    out = np.zeros(max_lag + 1)
    if total == 0.0:
        return out
    for lag in range(max_lag + 1):
        out[lag] = sum(float(np.dot(s[: s.size - lag], s[lag:])) for s in segments if s.size > lag) / total
    return out


@dataclass(frozen=True)
class ChannelAdequacy:
    channel: str
    unit: str
    floor: float  # the channel's noise floor (its sensor chain's)
    rms: float  # RMS of the residual, the ball's contact-noise outliers left out
    autocorrelation: tuple[float, ...]  # ρ(1…MAX_LAG) within windows
    band: float  # 1.96/√N: a white residual's ρ stays within it 95 % of the time
    outliers: int

    @property
    def ratio(self) -> float:
        return self.rms / self.floor

    @property
    def lag1(self) -> float:
        return self.autocorrelation[0] if self.autocorrelation else 0.0

    def to_json(self) -> dict[str, object]:
        return {
            "floor": self.floor,
            "rms": round(self.rms, 9),
            "rms_over_floor": round(self.ratio, 3),
            "autocorrelation": [round(r, 4) for r in self.autocorrelation],
            "white_band": round(self.band, 4),
            "outliers": self.outliers,
            "unit": self.unit,
        }


def channel_adequacy(
    residual: np.ndarray, *, channel: str, unit: str, floor: float, outlier: float = math.inf
) -> ChannelAdequacy:
    """``residual`` (windows, ticks): model − measurement of one channel."""
    e = np.asarray(residual, dtype=float)
    bad = ~(np.abs(e) <= outlier)
    e = np.where(bad, 0.0, e)
    n = int(e.size - bad.sum())
    power = float(np.sum(e * e))
    rms = math.sqrt(power / max(n, 1))
    rho = tuple(float(r) for r in autocorrelation(list(e), MAX_LAG)[1:])
    return ChannelAdequacy(channel, unit, floor, rms, rho, 1.96 / math.sqrt(max(n, 1)), int(bad.sum()))
