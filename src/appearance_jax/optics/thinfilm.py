"""Thin-film interference: the Airy film and coherent multilayer stacks (transfer matrices).

A film of index eta_1 and thickness d lies between an incidence medium eta_0 (real,
non-absorbing) and a substrate eta_2 (a dielectric, or a conductor n + i k). Light arrives
from the eta_0 side at angle theta_0. Per polarisation (s, p), with the signed complex
interface amplitudes of :func:`~appearance_jax.optics.fresnel.interface_amplitudes`
(written out again in real arithmetic inside :func:`airy`, its hot loop)
(Yeh 2005; Belcour & Barla 2017; spec M10 of Padrón 2025, which corrects the thesis):

    r = (r_01 + r_12 e^{i phi}) / (1 + r_01 r_12 e^{i phi})
    t = t_01 t_12 e^{i phi / 2} / (1 + r_01 r_12 e^{i phi})
    phi = (4 pi / lambda) eta_1 d cos(theta_1) = (4 pi / lambda) d q_1

    R = |r|^2,   T = Re(eta_2 cos theta_2 ...) / (eta_0 cos theta_0) |t|^2   (power flow, below)
    R_unpolarised = (R_s + R_p) / 2,   T_unpolarised = (T_s + T_p) / 2

q_j = eta_j cos theta_j = sqrt(eta_j^2 - eta_0^2 sin^2 theta_0) (forward branch,
:func:`~appearance_jax.optics.fresnel.normal_index`), so every case is one formula:
absorbing films and substrates (complex q), total internal reflection inside the film
or at the substrate (imaginary q: frustrated TIR through a thin film is included, and
T = 0 for a TIR substrate), and grazing incidence (r = -1, T = 0).

Misprint in the thesis (Padrón Eq. 3.1, [T:461] of seed 000): the expression
labelled I_R, with the prefactor n_2 cos theta_2 / (n_0 cos theta_0) and |t_01 t_12|^2 in
the numerator, is the *transmittance* of a non-absorbing film; R = 1 - T there. The
thesis' separate pi phase jumps (Padrón Eq. 3.3) are automatic here because the amplitudes
carry their signs. For real indices R + T = 1 (tested to 1e-12 in float64).

Power transmittance (Born & Wolf; tmm's convention): T_s = Re(q_2) / Re(q_0) |t_s|^2,
T_p = Re(eta_2 conj(cos theta_2)) / Re(eta_0 conj(cos theta_0)) |t_p|^2.

Multilayer stacks (:func:`multilayer`): the coherent transfer-matrix method (Yeh 2005;
Byrnes, "Multilayer optical calculations", arXiv:1603.02720) with each propagation matrix
normalised by e^{i delta_j} (|e^{i delta_j}| <= 1 for forward/decaying waves), so thick
absorbing layers cannot overflow; the product runs in a ``lax.scan`` over the layers.

Units: wavelengths and thicknesses in nm (any common length unit works: only d / lambda
matters). Everything broadcasts (angles x wavelengths x thicknesses x indices) and is
differentiable in the cosine, the wavelength, the thickness and the (real or complex)
indices; outputs are complex amplitudes or real intensities.

Wavelength-resolved colour (CIE integration, or the thesis' three wavelengths
650/510/475 nm, [T:526]) is :func:`film_rgb`; :func:`color_chart` is a thickness x angle
chart of the film's colour (Huang Fig. 3.3).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..core import spectral
from ..core.arrays import stacked
from .fresnel import interface_amplitudes, normal_index

POLARIZATIONS = ("unpolarized", "s", "p")


class FilmResponse(NamedTuple):
    """Complex amplitudes and real power coefficients of a film or stack, per polarisation."""

    r_s: jax.Array
    r_p: jax.Array
    t_s: jax.Array
    t_p: jax.Array
    R_s: jax.Array
    R_p: jax.Array
    T_s: jax.Array
    T_p: jax.Array

    @property
    def R(self):
        """Unpolarised reflectance (R_s + R_p) / 2."""
        return 0.5 * (self.R_s + self.R_p)

    @property
    def T(self):
        """Unpolarised transmittance (T_s + T_p) / 2 (power into the substrate)."""
        return 0.5 * (self.T_s + self.T_p)

    def reflectance(self, polarization: str = "unpolarized"):
        _check_pol(polarization)
        return {"unpolarized": self.R, "s": self.R_s, "p": self.R_p}[polarization]

    def transmittance(self, polarization: str = "unpolarized"):
        _check_pol(polarization)
        return {"unpolarized": self.T, "s": self.T_s, "p": self.T_p}[polarization]


def _check_pol(polarization):
    if polarization not in POLARIZATIONS:
        raise ValueError(f"polarization = {polarization!r}: must be one of {', '.join(POLARIZATIONS)}")


def _complex(x):
    x = jnp.asarray(x)
    return x if jnp.iscomplexobj(x) else x.astype(jnp.result_type(x, jnp.complex64))


def _incidence(cos0, eta0):
    """q_0 and the Snell invariant eta_0 sin theta_0 for a real cos0 in [0, 1]."""
    c = jnp.clip(jnp.asarray(cos0, dtype=jnp.result_type(cos0, float)), 0.0, 1.0)
    eta0 = jnp.asarray(eta0)
    # sin via the double-where: d sqrt(1 - c^2)/dc is infinite at normal incidence
    s2 = 1.0 - c * c
    pos = s2 > 0
    sin0 = jnp.where(pos, jnp.sqrt(jnp.where(pos, s2, 1.0)), 0.0)
    return _complex(eta0 * c), _complex(eta0 * sin0)


def _power(r_s, r_p, t_s, t_p, q0, qN, eta0, etaN):
    """Power coefficients from amplitudes (incidence medium eta0, exit medium etaN)."""
    eta0, etaN = _complex(eta0), _complex(etaN)
    cos0 = q0 / eta0
    cosN = qN / etaN
    den_s = jnp.real(q0)
    den_p = jnp.real(eta0 * jnp.conj(cos0))
    ok = den_s > 0
    den_s = jnp.where(ok, den_s, 1.0)
    den_p = jnp.where(ok, den_p, 1.0)
    T_s = jnp.where(ok, jnp.real(qN) / den_s * jnp.abs(t_s) ** 2, 0.0)
    T_p = jnp.where(ok, jnp.real(etaN * jnp.conj(cosN)) / den_p * jnp.abs(t_p) ** 2, 0.0)
    return FilmResponse(r_s, r_p, t_s, t_p, jnp.abs(r_s) ** 2, jnp.abs(r_p) ** 2, T_s, T_p)


# Complex numbers as (real, imaginary) pairs of real arrays. XLA:CPU's complex arithmetic
# (scaled division, complex sqrt/exp) made the film ~15x slower than this real formulation,
# and the film is the hot loop of every thin-film BSDF. Same formulas, same branches; the
# complex-typed reference is :func:`multilayer` (tested equal) and tmm.


def _cmul(a, b):
    return a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0]


def _cadd(a, b):
    return a[0] + b[0], a[1] + b[1]


def _csub(a, b):
    return a[0] - b[0], a[1] - b[1]


def _cdiv(a, b):
    d = b[0] * b[0] + b[1] * b[1]
    return (a[0] * b[0] + a[1] * b[1]) / d, (a[1] * b[0] - a[0] * b[1]) / d


def _cabs2(a):
    return a[0] * a[0] + a[1] * a[1]


def _csqrt_forward(x, y):
    """sqrt(x + i y) on the forward branch (Im >= 0; for y >= 0 the principal root).

    The stable textbook form: for x >= 0, re = sqrt((|z| + x)/2), im = y / (2 re); for
    x < 0, im = sqrt((|z| - x)/2), re = y / (2 im). Both branches are smooth where they are
    used (double-where), so gradients stay finite on the real axis, where |z| - x = 0.
    z = 0 exactly is nudged to machine epsilon, as :func:`~appearance_jax.optics.fresnel.normal_index`.
    """
    eps = jnp.finfo(jnp.result_type(x, float)).eps
    zero = (x == 0) & (y == 0)
    x = jnp.where(zero, eps, x)
    r = jnp.sqrt(x * x + y * y)
    pos = x >= 0
    a = jnp.sqrt(jnp.where(pos, 0.5 * (r + x), 1.0))
    b = jnp.sqrt(jnp.where(pos, 1.0, 0.5 * (r - x)))
    re = jnp.where(pos, a, y / (2.0 * b))
    im = jnp.where(pos, y / (2.0 * a), b)
    flip = im < 0  # only for y < 0 (gain media), outside the physical domain k >= 0
    return jnp.where(flip, -re, re), jnp.where(flip, -im, im)


def _split(z):
    z = jnp.asarray(z)
    if jnp.iscomplexobj(z):
        return jnp.real(z), jnp.imag(z)
    z = z.astype(jnp.result_type(z, float))
    return z, jnp.zeros_like(z)


def _interface_pairs(qi, qt, ei, et):
    """Signed amplitudes (r_s, r_p, t_s, t_p) as pairs; see fresnel.interface_amplitudes."""
    ei2, et2 = _cmul(ei, ei), _cmul(et, et)
    ds = _cadd(qi, qt)
    num_p = _csub(_cmul(et2, qi), _cmul(ei2, qt))
    dp = _cadd(_cmul(et2, qi), _cmul(ei2, qt))
    ok_s, ok_p = _cabs2(ds) > 0, _cabs2(dp) > 0
    ds = (jnp.where(ok_s, ds[0], 1.0), jnp.where(ok_s, ds[1], 0.0))
    dp = (jnp.where(ok_p, dp[0], 1.0), jnp.where(ok_p, dp[1], 0.0))

    def pick(ok, v, default):
        return jnp.where(ok, v[0], default), jnp.where(ok, v[1], 0.0)

    r_s = pick(ok_s, _cdiv(_csub(qi, qt), ds), 0.0)
    r_p = pick(ok_p, _cdiv(num_p, dp), 0.0)
    two_qi = (2.0 * qi[0], 2.0 * qi[1])
    t_s = pick(ok_s, _cdiv(two_qi, ds), 1.0)
    t_p = pick(ok_p, _cdiv(_cmul(_cmul(ei, et), two_qi), dp), 1.0)
    return r_s, r_p, t_s, t_p


def airy(cos0, wavelength_nm, thickness_nm, eta0, eta1, eta2) -> FilmResponse:
    """One film on a substrate: Airy amplitudes and power coefficients (spec M10, Padrón 2025).

    Args:
        cos0: cosine of the incidence angle in the eta0 medium, in [0, 1].
        wavelength_nm: vacuum wavelength (nm), > 0.
        thickness_nm: film thickness d (nm), >= 0 (d = 0 gives the bare eta0 | eta2 interface).
        eta0: index of the incidence medium (real).
        eta1: film index (real, or complex n + i k with k >= 0 for an absorbing film).
        eta2: substrate index (real, or complex for a conductor, k >= 0).

    Returns:
        :class:`FilmResponse` (r_s, r_p, t_s, t_p complex; R_s, R_p, T_s, T_p real; .R, .T
        unpolarised), broadcast over all arguments. Computed in real arithmetic (complex
        numbers as pairs); the complex outputs are assembled at the end, so code that only
        uses the powers never pays for them.
    """
    c = jnp.clip(jnp.asarray(cos0, dtype=jnp.result_type(cos0, float)), 0.0, 1.0)
    e0 = (jnp.asarray(eta0, dtype=c.dtype), jnp.zeros((), c.dtype))
    e1, e2 = _split(eta1), _split(eta2)
    s2 = (1.0 - c * c) * e0[0] * e0[0]  # (eta0 sin theta0)^2, the Snell invariant squared
    q0 = (e0[0] * c, jnp.zeros_like(c))

    def q(e):  # q = sqrt(eta^2 - s2) on the forward branch
        return _csqrt_forward(e[0] * e[0] - e[1] * e[1] - s2, 2.0 * e[0] * e[1])

    q1, q2 = q(e1), q(e2)
    r01s, r01p, t01s, t01p = _interface_pairs(q0, q1, e0, e1)
    r12s, r12p, t12s, t12p = _interface_pairs(q1, q2, e1, e2)
    k = 2.0 * jnp.pi / jnp.asarray(wavelength_nm) * jnp.asarray(thickness_nm)  # k0 d
    decay = jnp.exp(-k * q1[1])
    half = (decay * jnp.cos(k * q1[0]), decay * jnp.sin(k * q1[0]))  # e^{i phi/2}
    full = _cmul(half, half)

    def film(r01, r12, t01, t12):
        r12f = _cmul(r12, full)
        den = _cadd((1.0, 0.0), _cmul(r01, r12f))
        return _cdiv(_cadd(r01, r12f), den), _cdiv(_cmul(_cmul(t01, t12), half), den)

    (r_s, t_s), (r_p, t_p) = film(r01s, r12s, t01s, t12s), film(r01p, r12p, t01p, t12p)
    # power flow: T_s = Re(q2)/q0 |t_s|^2, T_p = Re(eta2 conj(cos2))/q0 |t_p|^2 (eta0, q0 real)
    ok = q0[0] > 0
    inv = jnp.where(ok, 1.0 / jnp.where(ok, q0[0], 1.0), 0.0)
    cos2 = _cdiv(q2, e2)
    flow_p = e2[0] * cos2[0] + e2[1] * cos2[1]  # Re(eta2 conj(cos2))
    cplx = jax.lax.complex
    return FilmResponse(cplx(*r_s), cplx(*r_p), cplx(*t_s), cplx(*t_p), _cabs2(r_s), _cabs2(r_p),
                        q2[0] * inv * _cabs2(t_s), flow_p * inv * _cabs2(t_p))


def airy_reflectance(cos0, wavelength_nm, thickness_nm, eta0, eta1, eta2, polarization: str = "unpolarized"):
    """Film reflectance R (unpolarised by default, or ``"s"`` / ``"p"``); see :func:`airy`."""
    return airy(cos0, wavelength_nm, thickness_nm, eta0, eta1, eta2).reflectance(polarization)


def airy_transmittance(cos0, wavelength_nm, thickness_nm, eta0, eta1, eta2, polarization: str = "unpolarized"):
    """Film transmittance T (power into the substrate); see :func:`airy`."""
    return airy(cos0, wavelength_nm, thickness_nm, eta0, eta1, eta2).transmittance(polarization)


@jax.custom_jvp
def airy_trt(cos_i, cos_o, wavelength_nm, thickness_nm, eta_film, melanin_reflectance):
    """Huang Eq. 5.3 (= F.3): film, melanin bounce, film again, for a free-standing film.

    A film of index ``eta_film`` in air (air | film | air) above a melanin layer (rock-dove
    barbules, Huang Fig. 5.4): the light crosses the film at ``cos_i`` (amplitude t of
    Eq. 5.1, multiple reflections included), is reflected by the melanin with intensity
    ``melanin_reflectance`` = |r_am|^2, and crosses the film again at ``cos_o`` (t'). The
    melanin scatters diffusely, so the two crossings add incoherently and per polarisation

        I_TRT = |t_s|^2 |r_am|^2 |t'_s|^2  (and the same for p),   I = (I_s + I_p) / 2,

    which is |t r_am t'_ak t'_ka / (1 - r'_ka^2 e^{i dpsi'})|^2 of Eq. 5.3, the film's
    transmittances T = |t|^2 at the two angles (air on both sides: no admittance factor).
    Symmetric in (cos_i, cos_o). cos in [0, 1]; lengths in nm. Derivatives (forward and reverse)
    come from a custom JVP that evaluates both crossings as one stacked film: the same values,
    half the compiled code.
    """
    one = jnp.ones((), jnp.result_type(cos_i, float))
    a = airy(cos_i, wavelength_nm, thickness_nm, one, eta_film, one)
    b = airy(cos_o, wavelength_nm, thickness_nm, one, eta_film, one)
    return jnp.asarray(melanin_reflectance) * 0.5 * (a.T_s * b.T_s + a.T_p * b.T_p)


def _airy_trt_stacked(cos_i, cos_o, wavelength_nm, thickness_nm, eta_film, melanin_reflectance):
    """:func:`airy_trt` with both crossings as one film evaluation on a leading axis of 2."""
    one = jnp.ones((), jnp.result_type(cos_i, float))
    f = airy(stacked(cos_i, cos_o, like=(wavelength_nm, thickness_nm, eta_film)), wavelength_nm, thickness_nm, one,
             eta_film, one)
    return jnp.asarray(melanin_reflectance) * 0.5 * (f.T_s[0] * f.T_s[1] + f.T_p[0] * f.T_p[1])


@airy_trt.defjvp
def _airy_trt_jvp(primals, tangents):
    # Derivatives come from the stacked form: XLA:CPU copies much of a film's reverse pass into
    # every fusion that reads it, so two films' reverse passes compiled to twice the code of one
    # stacked film (rock_dove's value-and-gradient: 120k -> 58k lines of optimised HLO, compile
    # 28 -> 13 s). Values stay with the two separate films, which run ~1.9x faster: fused into
    # their product, while the stacked film writes its (2, ...) outputs to memory first.
    return jax.jvp(_airy_trt_stacked, primals, tangents)


def film_period_nm(cos0, wavelength_nm, eta0, eta1):
    """Thickness period lambda / (2 Re q_1) of a non-absorbing film's response (nm).

    R is 2 pi-periodic in phi = 4 pi d q_1 / lambda (spec M10 (e)), so one period of d is
    the natural range for multi-start fits of a film thickness.
    """
    _, inv = _incidence(cos0, eta0)
    return jnp.asarray(wavelength_nm) / (2.0 * jnp.real(normal_index(eta1, inv)))


# --------------------------------------------------------------------------------------
# Multilayer stacks
# --------------------------------------------------------------------------------------


def multilayer(cos0, wavelength_nm, indices, thicknesses_nm) -> FilmResponse:
    """Coherent transfer-matrix solution of a stack of layers.

    Args:
        cos0: cosine of the incidence angle in the first medium, in [0, 1].
        wavelength_nm: vacuum wavelength (nm).
        indices: ``(..., L)`` indices from the incidence medium (index 0, real) to the exit
            medium (index L-1), L >= 2; real or complex.
        thicknesses_nm: ``(..., L-2)`` thicknesses of the inner layers (nm).

    The leading axes of ``indices`` and ``thicknesses_nm`` broadcast against ``cos0`` and
    ``wavelength_nm``. L = 3 is :func:`airy` (tested equal); L = 2 is a bare interface.

    Method: with interface matrices I_j = [[1, r_j], [r_j, 1]] / t_j and normalised
    propagation P_j = [[1, 0], [0, e^{2 i delta_j}]] (delta_j = 2 pi d_j q_j / lambda),
    M = I_0 P_1 I_1 ... P_{L-2} I_{L-2}; then r = M_10 / M_00 and
    t = prod_j e^{i delta_j} / M_00.
    """
    n = _complex(indices)
    d = jnp.asarray(thicknesses_nm)
    L = n.shape[-1]
    if L < 2:
        raise ValueError(f"multilayer: indices need at least 2 media (incidence, exit), got {L}")
    if d.shape[-1:] != (L - 2,) and not (L == 2 and d.size == 0):
        raise ValueError(f"multilayer: {L} media need {L - 2} inner thicknesses, got shape {d.shape}")
    eta0 = n[..., 0]
    q0, inv = _incidence(cos0, jnp.real(eta0))
    q = normal_index(n, inv[..., None])  # (..., L)
    k0 = 2.0 * jnp.pi / jnp.asarray(wavelength_nm)
    shape = jnp.broadcast_shapes(q.shape[:-1], jnp.shape(k0), d.shape[:-1] if d.ndim else ())
    q = jnp.broadcast_to(q, shape + (L,))
    n = jnp.broadcast_to(n, shape + (L,))
    q = q.at[..., 0].set(jnp.broadcast_to(q0, shape))

    def matrix(r, t):
        # [[1, r], [r, 1]] / t as (a, b, c, d)
        inv_t = 1.0 / t
        return (inv_t, r * inv_t, r * inv_t, inv_t)

    def mul(A, B):
        a, b, c, dd = A
        e, f, g, h = B
        return (a * e + b * g, a * f + b * h, c * e + dd * g, c * f + dd * h)

    # every interface j | j+1 at once; the first starts the product, the others are scanned
    rs, rp, ts, tp = interface_amplitudes(q[..., :-1], q[..., 1:], n[..., :-1], n[..., 1:])
    Ms = matrix(rs[..., 0], ts[..., 0])
    Mp = matrix(rp[..., 0], tp[..., 0])
    phase = jnp.ones(shape, dtype=q.dtype)
    if L > 2:
        # per inner layer j = 1..L-2: its propagation and the interface below it
        q_in = jnp.moveaxis(q[..., 1:-1], -1, 0)
        d_in = jnp.moveaxis(jnp.broadcast_to(d, shape + (L - 2,)), -1, 0)
        below = tuple(jnp.moveaxis(x[..., 1:], -1, 0) for x in (rs, rp, ts, tp))

        def step(carry, xs):
            Ms, Mp, phase = carry
            qj, dj, rs, rp, ts, tp = xs
            e = jnp.exp(1j * k0 * dj * qj)  # e^{i delta_j}, |e| <= 1 on the forward branch
            e2 = e * e

            def propagate(M):  # M diag(1, e^{2 i delta_j}): scales the second column
                return (M[0], M[1] * e2, M[2], M[3] * e2)

            Ms = mul(propagate(Ms), matrix(rs, ts))
            Mp = mul(propagate(Mp), matrix(rp, tp))
            return (Ms, Mp, phase * e), None

        (Ms, Mp, phase), _ = jax.lax.scan(step, (Ms, Mp, phase), (q_in, d_in) + below)
    r_s, r_p = Ms[2] / Ms[0], Mp[2] / Mp[0]
    t_s, t_p = phase / Ms[0], phase / Mp[0]
    return _power(r_s, r_p, t_s, t_p, q[..., 0], q[..., -1], n[..., 0], n[..., -1])


# --------------------------------------------------------------------------------------
# Colour
# --------------------------------------------------------------------------------------

def film_rgb(cos0, thickness_nm, eta0, eta1, eta2, *, mode: str = "cie", quantity: str = "reflectance",
             polarization: str = "unpolarized", illuminant: str = "D65"):
    """Linear sRGB of a film's reflectance (or transmittance), ``[..., 3]``.

    ``mode="cie"``: the spectrum on the 380-780 nm grid (5 nm as Huang 2022 [T:742] of
    seed 001) integrated with the CIE 1931 colour-matching functions under ``illuminant``
    and converted to white-balanced linear sRGB (a perfect reflector maps to (1, 1, 1);
    :func:`appearance_jax.core.spectral.cie_rgb_matrix`).
    ``mode="rgb3"``: the thesis' cheap mode, one wavelength per channel
    (650, 510, 475 nm, Padrón 2025 [T:526]), prone to spectral aliasing [T:526].
    """
    if mode not in ("cie", "rgb3"):
        raise ValueError(f"mode = {mode!r}: must be 'cie' or 'rgb3'")
    if quantity not in ("reflectance", "transmittance"):
        raise ValueError(f"quantity = {quantity!r}: must be 'reflectance' or 'transmittance'")
    wl = spectral.band_wavelengths(mode)
    resp = airy(jnp.asarray(cos0)[..., None], wl, jnp.asarray(thickness_nm)[..., None],
                jnp.asarray(eta0)[..., None], jnp.asarray(eta1)[..., None], jnp.asarray(eta2)[..., None])
    v = resp.reflectance(polarization) if quantity == "reflectance" else resp.transmittance(polarization)
    return spectral.to_bands(v, mode, illuminant=illuminant)


def color_chart(thickness_nm, theta_deg, eta0=1.0, eta1=1.33, eta2=1.0, *, mode: str = "cie", **kw):
    """Encoded sRGB colours of a film over thickness x angle, ``(n_thickness, n_angle, 3)`` in [0, 1].

    Huang Fig. 3.3 (seed 001, [T:519]): the colour bands bend towards larger
    thickness at oblique angles (the optical path difference 2 d eta_1 cos theta_1
    decreases with angle). Defaults: a free-standing soap film (eta_1 = 1.33). Linear
    colours are clipped to [0, 1] before encoding; keyword arguments go to :func:`film_rgb`.
    """
    d = jnp.asarray(thickness_nm)[:, None]
    c = jnp.cos(jnp.radians(jnp.asarray(theta_deg)))[None, :]
    rgb = film_rgb(c, d, eta0, eta1, eta2, mode=mode, **kw)
    return spectral.linear_to_srgb(jnp.clip(rgb, 0.0, 1.0))
