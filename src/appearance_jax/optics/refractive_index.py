"""Refractive-index models: wavelength (nm) -> real (n, k), the complex index being n + i k.

Every model is a small frozen pytree (:func:`~appearance_jax.core.params.params_class`), so its
coefficients can be fitted or differentiated like any other parameter. Calling a model
returns ``(n, k)`` with the shape of the wavelength array; ``model.complex(wl)`` returns
n + i k (k >= 0 absorbs, the convention of refractiveindex.info, ``tmm`` and Born & Wolf with
time dependence e^{-i omega t}).

| model        | formula (lambda in micrometres)                                  | coefficient units |
|--------------|------------------------------------------------------------------|-------------------|
| Constant     | n, k                                                             | 1                 |
| Cauchy       | n = A + B/lambda^2 + C/lambda^4 + D/lambda^6                     | um^2, um^4, um^6  |
| Sellmeier    | n^2 = 1 + sum_i B_i lambda^2 / (lambda^2 - C_i)                  | B: 1, C: um^2     |
| Tabulated    | linear interpolation of (wavelength_nm, n, k) rows               | nm, 1, 1          |
| Formula      | the nine dispersion formulas of refractiveindex.info (see below) | um powers         |
| Combined     | n from one model, k from another (a formula n + a ``tabulated k``) | -               |

Note the unit of the Cauchy coefficients: the keratin fit n = 1.532 + 5890/lambda^2 with lambda
in nm (Huang 2022 spec, §0.4-11) is ``Cauchy(A=1.532, B=5.89e-3)`` here.

Valid wavelength range: models that know one (Tabulated, Formula, Combined, or any model
given ``wavelength_range_nm``) raise a ``ValueError`` naming the material and the range when
called eagerly with a concrete wavelength outside it; inside ``jit`` (traced wavelengths)
they clamp the wavelength to the range instead, so kernels stay branch-free. The check
allows a relative slack of 1e-6 so that table end points converted from micrometres
(0.2 um -> 200.00000000000003 nm) still pass.

The refractiveindex.info formulas (``Formula.kind`` 1-9), with coefficients C1, C2, ... and
lambda in um (refractiveindex.info database documentation, "Dispersion formulas"):

1. Sellmeier:    n^2 - 1 = C1 + sum_i C_{2i} lambda^2 / (lambda^2 - C_{2i+1}^2)
2. Sellmeier-2:  n^2 - 1 = C1 + sum_i C_{2i} lambda^2 / (lambda^2 - C_{2i+1})
3. Polynomial:   n^2     = C1 + sum_i C_{2i} lambda^{C_{2i+1}}
4. RefractiveIndex.INFO:
                 n^2 = C1 + C2 lambda^C3 / (lambda^2 - C4^C5) + C6 lambda^C7 / (lambda^2 - C8^C9)
                       + sum_{i>=5} C_{2i} lambda^{C_{2i+1}}
5. Cauchy:       n       = C1 + sum_i C_{2i} lambda^{C_{2i+1}}
6. Gases:        n - 1   = C1 + sum_i C_{2i} / (C_{2i+1} - lambda^-2)
7. Herzberger:   n = C1 + C2/(lambda^2 - 0.028) + C3/(lambda^2 - 0.028)^2 + C4 lambda^2 + C5 lambda^4
                     + C6 lambda^6
8. Retro:        (n^2 - 1)/(n^2 + 2) = C1 + C2 lambda^2/(lambda^2 - C3) + C4 lambda^2
9. Exotic:       n^2 = C1 + C2/(lambda^2 - C3) + C4 (lambda - C5)/((lambda - C5)^2 + C6)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..core.arrays import is_concrete
from ..core.params import param, params_class, Real, static, validate
from ..core.special import safe_div, safe_sqrt

# Relative slack of the eager range check (see the module docstring).
_RANGE_SLACK = 1e-6


def _fmt_range(lo: float, hi: float) -> str:
    return f"[{lo:g}, {hi:g}] nm"


class _IndexModel:
    """Shared behaviour of the refractive-index pytrees (not a dataclass itself).

    Subclasses implement ``_nk(wl_nm) -> (n, k)`` (pure, jittable) and may override
    ``_range_nm() -> (lo, hi) | None`` (concrete floats, or None when unknown/traced).
    """

    def _label(self) -> str:
        name = getattr(self, "name", None)
        return f"{type(self).__name__} {name!r}" if name else type(self).__name__

    def _range_nm(self):
        r = getattr(self, "wavelength_range_nm", None)
        return None if r is None else (float(r[0]), float(r[1]))

    def _clamp_bounds(self):
        """Traceable (lo, hi) bounds used for clamping; None when the model has no range."""
        return self._range_nm()

    def check_wavelengths(self, wavelength_nm) -> None:
        """Eagerly raise ``ValueError`` if concrete wavelengths fall outside the valid range."""
        if not is_concrete(wavelength_nm):
            return
        r = self._range_nm()
        if r is None:
            return
        lo, hi = r
        wl = np.asarray(wavelength_nm, dtype=float)
        slack_lo, slack_hi = _RANGE_SLACK * abs(lo), _RANGE_SLACK * abs(hi)
        bad = ~np.isfinite(wl) | (wl < lo - slack_lo) | (wl > hi + slack_hi)
        if np.any(bad):
            first = float(wl[bad].flat[0]) if wl.ndim else float(wl)
            raise ValueError(
                f"{self._label()}: wavelength {first:g} nm is outside the valid range "
                f"{_fmt_range(lo, hi)}"
            )

    def __call__(self, wavelength_nm):
        """``(n, k)`` at ``wavelength_nm`` (any shape), both real arrays of that shape."""
        validate(self)
        self.check_wavelengths(wavelength_nm)
        return _evaluate(self, jnp.asarray(wavelength_nm, dtype=jnp.result_type(float)))

    def _clamped_nk(self, wl):
        b = self._clamp_bounds()
        if b is not None:
            # Clamping only matters inside jit (eager calls were checked above); it keeps
            # formulas away from their poles and tables from silent extrapolation.
            wl = jnp.clip(wl, b[0], b[1])
        n, k = self._nk(wl)
        shape = jnp.broadcast_shapes(jnp.shape(n), jnp.shape(k), jnp.shape(wl))
        return jnp.broadcast_to(n, shape), jnp.broadcast_to(k, shape)

    def complex(self, wavelength_nm):
        """Complex index n + i k."""
        n, k = self(wavelength_nm)
        return jax.lax.complex(n, k)


@jax.jit
def _evaluate(model, wl):
    # One compiled kernel per model class and static configuration (formula kind, range,
    # name), instead of op-by-op dispatch on every eager call.
    return model._clamped_nk(wl)


# --------------------------------------------------------------------------------------
# Analytic models
# --------------------------------------------------------------------------------------


@params_class
class Constant(_IndexModel):
    """Wavelength-independent index n + i k."""

    n: Real = param(1.5, lo=0.0, lo_open=True, unit="1", doc="real part of the refractive index")
    k: Real = param(0.0, lo=0.0, unit="1", doc="extinction coefficient")
    name: str = static("", doc="material name (for messages)")
    wavelength_range_nm: tuple | None = static(None, doc="optional valid range (lo, hi) in nm")

    def _nk(self, wl):
        zero = jnp.zeros_like(wl)
        return self.n + zero, self.k + zero


def _um(wl_nm):
    return wl_nm * 1e-3


@params_class
class Cauchy(_IndexModel):
    """Cauchy's dispersion n = A + B/lambda^2 + C/lambda^4 + D/lambda^6, lambda in um; k constant.

    Cauchy (1836); e.g. Hecht, *Optics*, §3.5. B in um^2, C in um^4, D in um^6.
    """

    A: Real = param(1.5, lo=0.0, lo_open=True, unit="1", doc="index at infinite wavelength")
    B: Real = param(0.0, unit="um^2", doc="coefficient of lambda^-2")
    C: Real = param(0.0, unit="um^4", doc="coefficient of lambda^-4")
    D: Real = param(0.0, unit="um^6", doc="coefficient of lambda^-6")
    k: Real = param(0.0, lo=0.0, unit="1", doc="extinction coefficient")
    name: str = static("", doc="material name (for messages)")
    wavelength_range_nm: tuple | None = static(None, doc="optional valid range (lo, hi) in nm")

    def _nk(self, wl):
        inv2 = 1.0 / (_um(wl) ** 2)
        n = self.A + inv2 * (self.B + inv2 * (self.C + inv2 * self.D))
        return n, self.k + jnp.zeros_like(wl)


@params_class
class Sellmeier(_IndexModel):
    """Sellmeier's dispersion n^2 = 1 + sum_i B_i lambda^2 / (lambda^2 - C_i), lambda in um.

    Sellmeier (1871); e.g. Born & Wolf §2.3.4. ``B`` and ``C`` are equal-length sequences
    (terms on the trailing axis); C in um^2 (the *squared* resonance wavelengths). The
    default is fused silica (Malitson 1965), valid 210-6700 nm. k is constant.
    Below a resonance (lambda^2 < C_i) n^2 may become negative; n is then clamped at 0.
    """

    B: Real = param((0.6961663, 0.4079426, 0.8974794), unit="1", doc="oscillator strengths")
    C: Real = param((0.0684043**2, 0.1162414**2, 9.896161**2), lo=0.0, unit="um^2",
                      doc="squared resonance wavelengths")
    k: Real = param(0.0, lo=0.0, unit="1", doc="extinction coefficient")
    name: str = static("", doc="material name (for messages)")
    wavelength_range_nm: tuple | None = static(None, doc="optional valid range (lo, hi) in nm")

    def _validate(self):
        if np.shape(self.B)[-1:] != np.shape(self.C)[-1:]:
            raise ValueError(
                f"Sellmeier.B and Sellmeier.C must have the same number of terms, got "
                f"{np.shape(self.B)} and {np.shape(self.C)}"
            )

    def _nk(self, wl):
        l2 = (_um(wl) ** 2)[..., None]
        terms = safe_div(self.B * l2, l2 - self.C)
        n = safe_sqrt(1.0 + jnp.sum(terms, axis=-1))
        return n, self.k + jnp.zeros_like(wl)


# --------------------------------------------------------------------------------------
# Tabulated data
# --------------------------------------------------------------------------------------


@params_class
class Tabulated(_IndexModel):
    """Linear interpolation of tabulated (wavelength_nm, n, k), e.g. Johnson & Christy 1972.

    ``wavelength_nm`` must be strictly increasing (checked eagerly). The valid range is
    [wavelength_nm[0], wavelength_nm[-1]]: outside, an eager call raises a ``ValueError``;
    a traced call returns the end values (clamped). ``k`` defaults to zeros.
    """

    wavelength_nm: Real = param((400.0, 700.0), lo=0.0, lo_open=True, unit="nm",
                                  doc="strictly increasing sample wavelengths")
    n: Real = param((1.5, 1.5), lo=0.0, unit="1", doc="real part of the index at the samples")
    # no lower bound: measured tables may dip below 0 in noisy bands (taken as given)
    k: Real | None = param(None, unit="1", doc="extinction coefficient at the samples (default 0)")
    name: str = static("", doc="material name (for messages)")

    def _validate(self):
        wl = np.asarray(self.wavelength_nm, dtype=float)
        n = np.asarray(self.n)
        k = n if self.k is None else np.asarray(self.k)
        if wl.ndim != 1 or wl.size < 1:
            raise ValueError(f"{self._label()}: wavelength_nm must be a non-empty 1-D array, got shape {wl.shape}")
        if n.shape != wl.shape or k.shape != wl.shape:
            raise ValueError(
                f"{self._label()}: wavelength_nm, n and k must have the same shape, got "
                f"{wl.shape}, {n.shape}, {k.shape}"
            )
        if np.any(np.diff(wl) <= 0):
            i = int(np.argmax(np.diff(wl) <= 0))
            raise ValueError(
                f"{self._label()}: wavelength_nm must be strictly increasing "
                f"({wl[i]:g} nm is followed by {wl[i + 1]:g} nm)"
            )

    def _range_nm(self):
        if not is_concrete(self.wavelength_nm):
            return None
        wl = np.asarray(self.wavelength_nm, dtype=float)
        return float(wl[0]), float(wl[-1])

    def _clamp_bounds(self):
        # jnp.interp already holds the end values outside the table; no explicit clamp.
        return None

    def _nk(self, wl):
        n = jnp.interp(wl, self.wavelength_nm, self.n)
        k = jnp.zeros_like(n) if self.k is None else jnp.interp(wl, self.wavelength_nm, self.k)
        return n, k


# --------------------------------------------------------------------------------------
# refractiveindex.info dispersion formulas
# --------------------------------------------------------------------------------------

FORMULA_NAMES = {
    1: "Sellmeier",
    2: "Sellmeier-2",
    3: "Polynomial",
    4: "RefractiveIndex.INFO",
    5: "Cauchy",
    6: "Gases",
    7: "Herzberger",
    8: "Retro",
    9: "Exotic",
}


def formula_coefficient_count_error(kind: int, count: int) -> str | None:
    """None if ``count`` coefficients suit formula ``kind``, else a description of what would."""
    if kind in (1, 2, 3, 5, 6):
        # C1 plus (multiplier, parameter) pairs
        return None if count >= 1 and count % 2 == 1 else "an odd number (C1 plus pairs), at least 1"
    if kind == 4:
        # C1, up to two 4-coefficient resonance groups, then (multiplier, exponent) pairs
        ok = count in (1, 5) or (count >= 9 and count % 2 == 1)
        return None if ok else "1, 5, or an odd number >= 9 (C1, two groups of 4, then pairs)"
    if kind == 7:
        return None if 1 <= count <= 6 else "between 1 and 6"
    if kind == 8:
        return None if 1 <= count <= 4 else "between 1 and 4"
    if kind == 9:
        return None if 1 <= count <= 6 else "between 1 and 6"
    return f"a known formula type (1-9), not {kind}"


def _pow(base, expo):
    """base ** expo for base >= 0 with finite gradients (0 ** 0 = 1, 0 ** e>0 = 0)."""
    pos = base > 0
    safe = jnp.where(pos, base, 1.0)
    return jnp.where(pos, jnp.exp(expo * jnp.log(safe)), jnp.where(expo == 0, 1.0, 0.0))


def _pad(c, size):
    """Coefficients padded with zeros to ``size`` (the absent terms of formulas 7-9 vanish)."""
    return jnp.concatenate([c, jnp.zeros((size - c.shape[-1],), c.dtype)]) if c.shape[-1] < size else c


def _term(mult, num, den):
    """mult * num / den, and exactly 0 when mult == 0 (so 0 * x / 0 never gives NaN)."""
    return jnp.where(mult == 0, 0.0, mult * safe_div(num, den))


def _formula_n(kind: int, c, lam):
    """n(lambda) of refractiveindex.info formula ``kind`` (lambda in um, coefficient array c)."""
    l2 = lam * lam
    lam_ = lam[..., None]
    l2_ = l2[..., None]
    if kind in (1, 2):
        mult, par = c[1::2], c[2::2]
        res = par * par if kind == 1 else par
        n2 = 1.0 + c[0] + jnp.sum(_term(mult, l2_, l2_ - res), axis=-1)
        return safe_sqrt(n2)
    if kind in (3, 5):
        s = c[0] + jnp.sum(c[1::2] * _pow(lam_, c[2::2]), axis=-1)
        return safe_sqrt(s) if kind == 3 else s
    if kind == 4:
        n2 = c[0]
        groups = min((c.shape[0] - 1) // 4, 2)
        for g in range(groups):  # at most two resonance terms: a static Python loop
            m, e1, b, e2 = c[1 + 4 * g], c[2 + 4 * g], c[3 + 4 * g], c[4 + 4 * g]
            n2 = n2 + _term(m, _pow(lam, e1), l2 - _pow(b, e2))
        if c.shape[0] > 9:
            n2 = n2 + jnp.sum(c[9::2] * _pow(lam_, c[10::2]), axis=-1)
        return safe_sqrt(n2)
    if kind == 6:
        mult, par = c[1::2], c[2::2]
        inv_l2 = (1.0 / l2)[..., None]
        return 1.0 + c[0] + jnp.sum(_term(mult, 1.0, par - inv_l2), axis=-1)
    if kind == 7:
        c = _pad(c, 6)
        L = 1.0 / (l2 - 0.028)  # 0.028 um^2 is part of Herzberger's formula
        return c[0] + c[1] * L + c[2] * L * L + l2 * (c[3] + l2 * (c[4] + l2 * c[5]))
    if kind == 8:
        c = _pad(c, 4)
        r = c[0] + _term(c[1], l2, l2 - c[2]) + c[3] * l2
        # Lorentz-Lorenz form solved for n^2: n^2 = (1 + 2 r) / (1 - r)
        return safe_sqrt(safe_div(1.0 + 2.0 * r, 1.0 - r))
    if kind == 9:
        c = _pad(c, 6)
        d = lam - c[4]
        n2 = c[0] + _term(c[1], 1.0, l2 - c[2]) + _term(c[3], d, d * d + c[5])
        return safe_sqrt(n2)
    raise ValueError(f"unknown refractiveindex.info formula type {kind}; known types are 1-9")


@params_class
class Formula(_IndexModel):
    """A refractiveindex.info dispersion formula (``kind`` 1-9, see the module docstring); k = 0.

    ``coefficients`` C1, C2, ... in the formula's micrometre units; ``wavelength_range_nm``
    is the validity range stated by the data file.
    """

    kind: int = static(1, choices=tuple(range(1, 10)), doc="refractiveindex.info formula number")
    coefficients: Real = param((0.0,), unit="um powers", doc="C1, C2, ... of the formula")
    wavelength_range_nm: tuple | None = static(None, doc="valid range (lo, hi) in nm")
    name: str = static("", doc="material name (for messages)")

    def _validate(self):
        c = np.asarray(self.coefficients)
        err = formula_coefficient_count_error(self.kind, c.shape[-1] if c.ndim else 0)
        if c.ndim != 1 or err is not None:
            raise ValueError(
                f"{self._label()}: formula {self.kind} ({FORMULA_NAMES[self.kind]}) got "
                f"{c.shape[-1] if c.ndim else 0} coefficients; expected {err}"
            )

    def _nk(self, wl):
        n = _formula_n(self.kind, jnp.asarray(self.coefficients), _um(wl))
        return n, jnp.zeros_like(wl)


# --------------------------------------------------------------------------------------
# Composition
# --------------------------------------------------------------------------------------


@params_class
class Combined(_IndexModel):
    """n from ``n_model`` and k from ``k_model`` (e.g. a formula n with a ``tabulated k``).

    The valid range is the intersection of both models' ranges.
    """

    n_model: object = None
    k_model: object = None
    name: str = static("", doc="material name (for messages)")

    def _validate(self):
        validate(self.n_model)
        validate(self.k_model)

    def _range_nm(self):
        ranges = [r for r in (self.n_model._range_nm(), self.k_model._range_nm()) if r is not None]
        if not ranges:
            return None
        return max(r[0] for r in ranges), min(r[1] for r in ranges)

    def _clamp_bounds(self):
        return self._range_nm()

    def _nk(self, wl):
        return self.n_model._nk(_clip_to(self.n_model, wl))[0], self.k_model._nk(_clip_to(self.k_model, wl))[1]


def _clip_to(model, wl):
    b = model._clamp_bounds()
    return wl if b is None else jnp.clip(wl, b[0], b[1])


RefractiveIndex = Constant | Cauchy | Sellmeier | Tabulated | Formula | Combined

__all__ = [
    "Constant",
    "Cauchy",
    "Sellmeier",
    "Tabulated",
    "Formula",
    "Combined",
    "FORMULA_NAMES",
    "formula_coefficient_count_error",
    "RefractiveIndex",
]
