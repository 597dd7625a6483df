"""Tone mapping of the report's maps: log luminance, so a specular peak and the diffuse part both show.

A glossy BRDF spans 3-6 decades between its mirror peak and its diffuse floor, so a linear
exposure (the brightest 1 % white) leaves everything but the peak black. :class:`LogTone`
maps the **log10 luminance** of f cos theta_o linearly to the displayed sRGB **value**
(brightness) and keeps the hue and saturation of the linear-sRGB colour:

    L     = clip(log10(Y / lo) / log10(hi / lo), 0, 1 + headroom)       Y = luminance (Rec. 709)
    v     = V_LO + (V_HI - V_LO) L                                       (sRGB-encoded value)
    shown = rgb / max(rgb) * srgb_to_linear(v), sRGB-encoded

so ``lo`` is shown dark grey (not black: black is kept for "no sample"), ``hi`` almost white,
values up to ``HEADROOM`` x the range above ``hi`` (a fit that overshoots the peak) still
brighten, and each decade takes the same step of brightness. Values at or below ``lo`` (zeros
included) are shown at the darkest level. The same :class:`LogTone` draws the measured and the
fitted panel, so their brightness compares directly; :meth:`LogTone.colorbar` states the range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...core.spectral import LUMINANCE_WEIGHTS, linear_to_srgb, srgb_to_linear

__all__ = ["LogTone", "log_tone", "symmetric_limit", "V_LO", "V_HI"]

V_LO = 0.18  # sRGB value of the bottom of the range (dark grey, distinct from black = no sample)
V_HI = 0.9  # sRGB value of the top of the range (the measured peak)
HEADROOM = (1.0 - V_HI) / (V_HI - V_LO)  # fraction of the range above hi before white


def _luminance(rgb) -> np.ndarray:
    return np.asarray(rgb, np.float64) @ LUMINANCE_WEIGHTS


@dataclass(frozen=True)
class LogTone:
    """Log-luminance tone map from ``lo`` to ``hi`` (luminance of f cos theta_o, 1/sr)."""

    lo: float
    hi: float

    def __post_init__(self):
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and 0.0 < self.lo < self.hi):
            raise ValueError(f"LogTone: need 0 < lo < hi (finite), got lo={self.lo!r}, hi={self.hi!r}")

    @property
    def decades(self) -> float:
        """log10(hi / lo)."""
        return math.log10(self.hi / self.lo)

    def level(self, rgb) -> np.ndarray:
        """The position L in the range (0 at ``lo``, 1 at ``hi``) of each colour's luminance (..., 3)."""
        y = _luminance(rgb)
        with np.errstate(divide="ignore", invalid="ignore"):
            lvl = np.log10(np.maximum(y, self.lo) / self.lo) / self.decades
        return np.clip(np.where(np.isfinite(y), lvl, np.nan), 0.0, 1.0 + HEADROOM)

    def __call__(self, rgb) -> np.ndarray:
        """sRGB-encoded colours in [0, 1] (..., 3) of linear-sRGB values (..., 3); NaN stays NaN."""
        rgb = np.asarray(rgb, np.float64)
        lvl = self.level(rgb)
        v = np.clip(V_LO + (V_HI - V_LO) * lvl, 0.0, 1.0)
        pos = np.maximum(np.nan_to_num(rgb, nan=0.0), 0.0)
        peak = pos.max(axis=-1, keepdims=True)
        hue = np.where(peak > 0, pos / np.where(peak > 0, peak, 1.0), 1.0)  # grey where no positive channel
        lin = hue * np.asarray(srgb_to_linear(v), np.float64)[..., None]
        out = np.clip(np.asarray(linear_to_srgb(lin), np.float64), 0.0, 1.0)
        return np.where(np.isnan(lvl)[..., None], np.nan, out)

    def describe(self) -> str:
        """One line: what the brightness shows and its range."""
        return (f"brightness = log10 luminance of f cos theta_o from {self.lo:.3g} to {self.hi:.3g} 1/sr "
                f"({self.decades:.1f} decades; lower values at the darkest level), hue = linear-sRGB chromaticity")

    def colorbar(self, fig, axes, label=None, cax=None):
        """A grey-ramp colour bar beside ``axes`` (or in ``cax``) with log ticks in 1/sr (the
        brightness a grey sample takes)."""
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import ListedColormap, LogNorm

        ramp = np.linspace(V_LO, V_HI, 256)
        sm = ScalarMappable(norm=LogNorm(self.lo, self.hi), cmap=ListedColormap(np.stack([ramp] * 3, axis=1)))
        sm.set_array([])
        return fig.colorbar(sm, ax=axes, cax=cax, label=label or r"luminance of $f\cos\theta_o$ [1/sr] (log scale)")


def log_tone(rgb, *, max_decades: float = 6.0, min_decades: float = 1.0) -> LogTone:
    """The :class:`LogTone` of the linear-sRGB values ``rgb`` (..., 3; NaN ignored): ``hi`` = the
    largest luminance, ``lo`` = the smallest positive one rounded down to a power of ten, kept
    within [``min_decades``, ``max_decades``] decades below ``hi``. No positive value: 1e-3 to 1."""
    if not (1.0 <= min_decades <= max_decades <= 12.0):
        raise ValueError(f"log_tone: need 1 <= min_decades <= max_decades <= 12, got {min_decades}, {max_decades}")
    y = _luminance(np.asarray(rgb, np.float64).reshape(-1, 3))
    y = y[np.isfinite(y) & (y > 0)]
    if y.size == 0:
        return LogTone(1e-3, 1.0)
    hi = float(y.max())
    lo = 10.0 ** math.floor(math.log10(float(y.min())))
    lo = min(max(lo, hi * 10.0 ** -max_decades), hi * 10.0 ** -min_decades)
    return LogTone(lo, hi)


def symmetric_limit(values, *, steps=(0.05, 0.1, 0.2, 0.5, 1.0, 2.0)) -> float:
    """The smallest of ``steps`` at or above the 99th percentile of |values| (finite ones), else the
    largest: the symmetric colour limits of a residual map (values beyond it saturate)."""
    v = np.abs(np.asarray(values, np.float64))
    v = v[np.isfinite(v)]
    q = float(np.percentile(v, 99)) if v.size else 0.0
    return next((s for s in steps if s >= q), steps[-1])
