"""Lorenz–Mie phase function of a homogeneous sphere (Bohren & Huffman 1983 §4.4; the exact
reference of Sadeghi 2011 Ch. 3, L1140; spec seed-002 §1.2.6).

    p(theta) = (|S1|^2 + |S2|^2) / (2 pi x^2 Q_sca)        [1/sr],  integral over the sphere = 1

with S1, S2, Q_sca of :mod:`appearance_jax.phase.mie_series`, the size parameter
``x = 2 pi a n_medium / lambda`` and the relative index ``m = (n_particle + i k_particle) /
n_medium``. Directions point away from the scatterer (the convention of
:mod:`~appearance_jax.phase.henyey_greenstein`): light propagates along ``-wi``, the
scattering angle is ``cos theta = -(wi . wo)``, forward scattering is ``wo = -wi``.
Reciprocal; no horizon.

| parameter     | default | range        | unit | meaning                                         |
|---------------|---------|--------------|------|-------------------------------------------------|
| radius_um     | 0.5     | (0, 1e4]     | µm   | sphere radius a                                  |
| wavelength_nm | 550     | [100, 1e5]   | nm   | vacuum wavelength, per band                      |
| n_particle    | 1.33    | (0, 20]      | 1    | real index of the sphere, per band               |
| k_particle    | 0       | [0, 20]      | 1    | imaginary index (absorption), per band           |
| n_medium      | 1       | [1, 5]       | 1    | real index of the surrounding medium, per band   |
| terms (static)| auto    | >= 1         |      | series length (>= x + 4 x^(1/3) + 2 per band)   |

``terms`` is static (it sets the compiled program). Left at ``None`` it is chosen when the
Params is built from concrete values: the Wiscombe length of the largest band's x, rounded
up to a multiple of 32 so that nearby radii share one compiled program. When fitting the
radius, build the starting Params with ``terms=terms_for(largest radius, ...)``: a traced x
beyond the capacity of ``terms`` would be silently truncated (eager calls check it).
``|m| <= 6`` (:data:`~appearance_jax.phase.mie_series.MAX_INDEX`).

Sampling: the band-mean phase function tabulated on ``TABLE_BINS`` bins in ``mu = cos theta``
(bin edges crowded towards the forward peak, widths ~ 2/TABLE_BINS in theta there), piecewise
constant in mu inside each bin, mixed with 1 % of the uniform density so that no direction
has zero density; ``pdf()`` returns that same density and ``weight = f / pdf`` per band, so
the estimator is unbiased whatever the table's resolution (a narrow forward peak at large
x only raises the variance).

Precision: float64 (``jax_enable_x64``) is needed for x >~ 100 (see mie_series).

Example::

    import jax; jax.config.update("jax_enable_x64", True)
    from appearance_jax.phase import mie
    p = mie.Params(radius_um=10.0, wavelength_nm=(650.0, 510.0, 475.0), n_particle=1.331)
    q = mie.efficiencies(p)            # Q_ext, Q_sca, Q_back, g per band
    f = mie.phase_function(p, jnp.cos(jnp.radians(138.0)))
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core.arrays import is_concrete
from ..core.model import Model, as_bands, boundary, with_bands
from ..core.params import Bands, Real, integer, param, params_class, static
from ..core.vec import dot
from . import binned
from . import mie_series as S

#: bins of the sampling table in mu = cos(theta)
TABLE_BINS = 1024
_TERMS_QUANTUM = 32


def _x_and_m(radius_um, wavelength_nm, n_particle, k_particle, n_medium):
    x = 2.0 * np.pi * radius_um * 1e3 * n_medium / wavelength_nm
    return x, (n_particle + 1j * k_particle) / n_medium


def terms_for(radius_um, wavelength_nm, n_medium=1.0) -> int:
    """Series length for the largest size parameter of concrete inputs, rounded up to a
    multiple of 32 (so nearby radii share one compiled program)."""
    x, _ = _x_and_m(np.asarray(radius_um, float), np.asarray(wavelength_nm, float), 0.0, 0.0,
                    np.asarray(n_medium, float))
    n = S.series_length(x)
    return int(math.ceil(n / _TERMS_QUANTUM) * _TERMS_QUANTUM)


@params_class
class Params:
    radius_um: Real = param(0.5, lo=0.0, hi=1e4, lo_open=True, unit="um", doc="sphere radius")
    wavelength_nm: Bands = param(550.0, lo=100.0, hi=1e5, unit="nm", doc="vacuum wavelength", bands=True)
    n_particle: Bands = param(1.33, lo=0.0, hi=20.0, lo_open=True, unit="1", doc="real index of the sphere",
                              bands=True)
    k_particle: Bands = param(0.0, lo=0.0, hi=20.0, unit="1", doc="imaginary index of the sphere", bands=True)
    n_medium: Bands = param(1.0, lo=1.0, hi=5.0, unit="1", doc="index of the surrounding medium", bands=True)
    terms: int | None = static(None, doc="series length (static); None: chosen from the concrete values",
                               convert=lambda v: None if v is None else integer(1)(v))

    def __post_init__(self):
        if self.terms is None and is_concrete(*(getattr(self, f) for f in type(self)._data_fields)):
            object.__setattr__(self, "terms", terms_for(np.asarray(self.radius_um), np.asarray(self.wavelength_nm),
                                                        np.asarray(self.n_medium)))

    def _validate(self):
        x, m = _x_and_m(np.asarray(self.radius_um, float), np.asarray(self.wavelength_nm, float),
                        np.asarray(self.n_particle, float), np.asarray(self.k_particle, float),
                        np.asarray(self.n_medium, float))
        need = S.series_length(x)
        if self.terms < need:
            raise ValueError(f"mie.Params.terms = {self.terms} is too short for the size parameter "
                             f"x = {float(np.max(x)):.6g}: it needs >= {need} (x + 4 x^(1/3) + 2); "
                             f"leave terms=None or use terms_for(...)")
        am = float(np.max(np.abs(m)))
        if am > S.MAX_INDEX:
            raise ValueError(f"mie.Params: relative index |m| = {am:.6g} is outside the valid range "
                             f"(0, {S.MAX_INDEX}]")


class Efficiencies(NamedTuple):
    """Per band: extinction, scattering and backscattering efficiencies (cross-section /
    pi a^2) and the asymmetry parameter g = <cos theta>."""

    q_ext: jax.Array
    q_sca: jax.Array
    q_back: jax.Array
    g: jax.Array


def _coefficients(p: Params):
    if p.terms is None:
        raise ValueError("mie.Params.terms is None: give terms (e.g. terms_for(...)) when building "
                         "Params from traced values")
    lam = as_bands(p.wavelength_nm)
    n_med = as_bands(p.n_medium)
    x = 2.0 * jnp.pi * jnp.asarray(p.radius_um)[..., None] * 1e3 * n_med / lam
    m = (as_bands(p.n_particle) + 1j * as_bands(p.k_particle)) / n_med
    x, m = jnp.broadcast_arrays(x, m)
    a, b = S.coefficients(m, x, p.terms)
    return a, b, x


def _efficiencies(p: Params) -> Efficiencies:
    a, b, x = _coefficients(p)
    return Efficiencies(*S.efficiencies(a, b, x))


def _amplitudes(p: Params, cos_theta):
    """(S1, S2), shape ``cos_theta.shape + (bands,)`` (Bohren & Huffman normalisation)."""
    a, b, x = _coefficients(p)
    return S.amplitudes(a, b, cos_theta)


def _phase_of(a, b, x, cos_theta):
    S1, S2 = S.amplitudes(a, b, jnp.clip(cos_theta, -1.0, 1.0))
    _, q_sca, _, _ = S.efficiencies(a, b, x)
    return (jnp.abs(S1) ** 2 + jnp.abs(S2) ** 2) / (2.0 * jnp.pi * x * x * q_sca)


def _phase(p: Params, cos_theta):
    return _phase_of(*_coefficients(p), cos_theta)


def _table(a, b, x):
    """Bin edges in mu (decreasing, crowded towards the forward peak: mu = 1 - 2 t^2 on uniform
    t, so theta ~ 2 t there) and bin probabilities of the band-mean phase function."""
    t = jnp.linspace(0.0, 1.0, TABLE_BINS + 1, dtype=jnp.result_type(float))
    edges = 1.0 - 2.0 * t * t
    f = jnp.mean(_phase_of(a, b, x, edges), axis=-1)  # (bins + 1,)
    mass = 0.5 * (f[:-1] + f[1:]) * (edges[:-1] - edges[1:])
    return edges, binned.probabilities(mass, edges)


def _eval(p: Params, wi, wo):
    return _phase(p, -dot(wi, wo))


def _pdf(p: Params, wi, wo):
    edges, prob = _table(*_coefficients(p))
    return binned.density(edges, prob, -dot(wi, wo))


def _sample(p: Params, wi, u):
    a, b, x = _coefficients(p)  # once: the table and the weights share the series
    edges, prob = _table(a, b, x)
    wo, c = binned.sample(edges, prob, wi, u)
    pdf = binned.density(edges, prob, c)
    return wo, _phase_of(a, b, x, c) / with_bands(pdf), pdf


eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)
efficiencies = boundary(_efficiencies, Params)
efficiencies.__doc__ = """Q_ext, Q_sca, Q_back, g per band (:class:`Efficiencies`)."""
amplitudes = boundary(_amplitudes, Params)
amplitudes.__doc__ = """Scattering amplitudes (S1 ⊥, S2 ∥) at ``cos_theta`` (theta from the forward
direction), complex, shape ``cos_theta.shape + (bands,)``, Bohren & Huffman normalisation:
(1/(pi a^2)) dsigma/dOmega = |S_j|^2 / (pi x^2) per polarisation."""
phase_function = boundary(_phase, Params)
phase_function.__doc__ = """p(theta) per band [1/sr] at ``cos_theta`` (theta from the forward direction)."""

MODEL = Model(
    name="mie",
    kind="phase",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="Lorenz-Mie phase function of a homogeneous sphere (radius, wavelength, complex index)",
    source="Bohren & Huffman 1983 §4.4; Sadeghi 2011 Ch. 3 reference (seed-002 spec §1.2.6)",
    reciprocal=True,
    transmissive=True,
    presets={
        "rayleigh": Params(radius_um=0.02, wavelength_nm=(650.0, 510.0, 475.0), n_particle=1.5),
        "haze": Params(radius_um=0.3, wavelength_nm=(650.0, 510.0, 475.0), n_particle=1.33),
        "soot": Params(radius_um=0.1, wavelength_nm=550.0, n_particle=1.75, k_particle=0.43),
        "fog": Params(radius_um=3.0, wavelength_nm=(650.0, 510.0, 475.0), n_particle=1.331),
    },
)
