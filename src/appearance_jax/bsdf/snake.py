"""Snake skin: a smooth iridescent thin film over an absorbing diffuse layer (Padrón 2025, Ch. 3).

Two layers, nothing between them, everything azimuth-independent (spec M26/M38, §2.1):

* **Layer 0, the film** (Padrón Eqs. 3.4-3.5): a smooth delta interface that mirrors
  with the Airy reflectance R(mu, lambda) and transmits **straight through** (no refraction,
  the thesis' convention) with T = 1 - R:

      f_0(wi, wo) = R(mu_i) delta(wo - mirror(wi)) + (1 - R(mu_i)) delta(wo + wi)

  R is :func:`appearance_jax.optics.thinfilm.airy` for the film (eta_1, thickness delta_0)
  between eta_0 (above) and eta_2 (below), unpolarised, one value per wavelength. (The
  printed Padrón Eq. 3.1 is the film's *transmittance*; the spec's M10 correction is used.)
* **Layer 1, the absorbing diffuse BRDF** (Padrón Eq. 3.6), mu = |n . w|:

      "product" (printed, default):  f_1 = k_d / pi exp(-sigma_a delta_1 / (mu_i mu_o))
      "beer_sum" (physical double pass, spec [OCR-FIX]):
                                    f_1 = k_d / pi exp(-sigma_a delta_1 (1 / mu_i + 1 / mu_o))

  Both coincide at mu_i = mu_o = 1/2. Only the optical depth sigma_a delta_1 matters (the
  thesis prints delta_1 in "nm"; the unit of sigma_a is whatever makes the product
  dimensionless). Albedo of f_1: 2 k_d E_3(tau / mu_i) (product) or
  2 k_d e^{-tau / mu_i} E_3(tau) (beer_sum), tau = sigma_a delta_1.

**Composition** (spec M26 [DERIVED]). Light enters through the film (T(mu_i)), bounces
between f_1 and the film's underside (reflectance R_u(mu)) any number of times and leaves
through the film (T_u(mu_o) = 1 - R_u(mu_o)):

    f(wi, wo) = R(mu_i) delta_mirror + f_d(wi, wo),     f_d = T(mu_i) F(mu_i, mu_o) T_u(mu_o)
    F(mu_i, mu_o) = f_1(mu_i, mu_o) + 2 pi int_0^1 f_1(mu_i, mu') mu' R_u(mu') F(mu', mu_o) dmu'

**Nyström solution** (spec M38). With quadrature nodes mu_k and weights w_k on [0, 1],
D_k = 2 pi w_k mu_k R_u(mu_k), the kernel K_jk = f_1(mu_j, mu_k) D_k and
u(mu)_k = f_1(mu, mu_k), the collocation equations at mu_i = mu_j give the column
F(., mu_o) = (I - K)^{-1} u(mu_o) for *any* mu_o, and the Nyström interpolation at any mu_i:

    F(mu_i, mu_o) = f_1(mu_i, mu_o) + u(mu_i)^T M u(mu_o),     M = diag(D) (I - K)^{-1}

M is symmetric, so F is symmetric (symmetrised numerically: reciprocity holds to
rounding). The directional albedo of f_d uses the same rule. One (n, n) solve per band and
parameter set, then O(n^2) per direction pair; exact to the quadrature, jittable,
vmappable and differentiable. The rule is Gauss-Legendre on two panels split at the cosine
of total internal reflection under the film (if any), so the convergence stays spectral;
thick films (R oscillating many times over mu) need more nodes: raise ``n_nodes``.

**What ``eval`` returns.** ``eval`` is the *non-delta* part f_d (1/sr, bands trailing); the
mirror lobe's weight R(mu_i) is :func:`specular` (the spec's ``delta_weight``). A path
tracer picks the mirror with probability R / (R + A_d) (band averages; A_d = :func:`albedo`,
the directional albedo of f_d, spec §2.1.4) -- :func:`sample_full` does that. ``sample`` /
``pdf`` cover f_d only: cosine-weighted hemisphere, pdf = mu_o / pi, weight = pi f_d.
mu <= 0 (below the horizon or grazing) gives exactly 0 with finite gradients.

**Underside reflectance** (static ``underside``): ``"top"`` (default, spec decision D14)
reuses the top-side R(mu); ``"airy"`` takes the Airy R seen from the eta_2 side (total
internal reflection for eta_2 > eta_0), which conserves energy but is **not reciprocal**
when eta_2 != eta_0. ``Model.reciprocal`` refers to the default.

**Colour** (static ``color``, :data:`appearance_jax.core.spectral.COLOR_MODES`):
``"rgb3"`` evaluates at 650/510/475 nm (R, G, B; [T:526], prone to spectral aliasing);
``"spectral"`` at the static ``wavelengths`` (one band each); ``"cie"`` on the 380-780 nm
5-nm grid, converted to linear sRGB under D65 at the end (``to_bands``; f is linear in the
spectrum, so the conversion of the BSDF value is exact). ``kd`` and ``sigma_a`` live on the
wavelengths of the computation: a scalar, or one value per wavelength (3 for rgb3,
``len(wavelengths)`` for spectral, 81 for cie).

With k_d = 0 (Padrón Figs. 3.5 and 3.6(d)) f_d = 0 and the absorption has no
effect (flagged Q-S5).

| parameter  | default    | range       | unit           | meaning                                          |
|------------|------------|-------------|----------------|--------------------------------------------------|
| thickness  | 900        | [0, 5000]   | nm             | film thickness delta_0                           |
| eta0       | 1.0        | [1, 3]      | 1              | index of the top medium (air)                    |
| eta1       | 1.56       | [1, 3]      | 1              | film index (keratin; Padrón Table 3.1 prints 1.53) |
| eta2       | 1.0        | [1, 3]      | 1              | index of the medium below the film               |
| sigma_a    | 0.7        | [0, inf)    | 1/depth unit   | absorption coefficient, per wavelength           |
| depth      | 2.0        | [0, inf)    | "nm" (thesis)  | absorbing-layer thickness delta_1 (*)            |
| kd         | 0.3        | [0, 1]      | 1              | albedo of the diffuse reflector, per wavelength  |
| absorption | "product"  | product, beer_sum | -        | Padrón Eq. 3.6 as printed, or the Beer double pass |
| underside  | "top"      | top, airy   | -              | film reflectance seen from below (D14)           |
| color      | "rgb3"     | rgb3, cie, spectral | -      | output bands                                     |
| wavelengths| (650, 510, 475) | > 0    | nm             | wavelengths of the "spectral" mode               |
| n_nodes    | 48         | [8, 1024]   | -              | quadrature nodes of the Nyström solve            |

Defaults: the values of Padrón Sec. 3.5.2 (eta_1 = 1.56, sigma_a = 0.7, delta_1 = 2,
delta_0 = 900 nm of Padrón Fig. 3.6(c)) with k_d = 0.3 (the diffuse baseline of Padrón
Fig. 3.6(a)) so that the layer is visible. (*) Only the optical depth sigma_a delta_1 enters.

Public functions: ``eval`` / ``sample`` / ``pdf`` (the model protocol, non-delta part),
:func:`specular` (delta weight), :func:`albedo` (directional albedo of f_d),
:func:`components` (all three from one solve), :func:`sample_full` (delta + diffuse, for a
path tracer) and :func:`eval_mc`, an independent position-free random walk (next-event
estimation at every bottom vertex, cosine-sampled bounces, the underside reflection taken
as a weight or by Russian roulette) that returns the estimate of f_d and its standard error.

Measured accuracy of the quadrature, the decisions (D14, Q-S5) and their history, cost
notes: docs/thin_films.md.

Example::

    from appearance_jax.bsdf import snake
    from appearance_jax.core.frame import spherical_direction
    p = snake.Params()                      # or snake.PRESETS["table_3_1"]
    wi, wo = spherical_direction(0.3, 0.0), spherical_direction(0.6, 2.0)
    f_d = snake.eval(p, wi, wo)             # (3,) 1/sr, the non-delta part
    R = snake.specular(p, wi)               # (3,) weight of the mirror lobe
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..core import spectral, warp
from ..core.linalg import solve_diagonally_dominant
from ..core.model import Model, as_bands, boundary, with_bands
from ..core.params import Bands, check_int, integer, param, params_class, Real, static
from ..core.quadrature import gauss_legendre
from ..core.rng import is_prng_key, uniforms
from ..core.vec import Vec3
from ..optics.thinfilm import airy

ABSORPTION_FORMS = ("product", "beer_sum")
UNDERSIDE_MODES = ("top", "airy")


@params_class
class Params:
    thickness: Real = param(900.0, lo=0.0, hi=5000.0, unit="nm", doc="film thickness delta_0")
    eta0: Real = param(1.0, lo=1.0, hi=3.0, unit="1", doc="index of the top medium")
    eta1: Real = param(1.56, lo=1.0, hi=3.0, unit="1", doc="index of the film (keratin)")
    eta2: Real = param(1.0, lo=1.0, hi=3.0, unit="1", doc="index of the medium below the film")
    sigma_a: Bands = param(0.7, lo=0.0, unit="1/depth unit", doc="absorption coefficient, per wavelength",
                            bands=True)
    depth: Real = param(2.0, lo=0.0, unit="nm (thesis)",
                          doc="absorbing-layer thickness delta_1 (only sigma_a * depth matters)")
    kd: Bands = param(0.3, lo=0.0, hi=1.0, unit="1", doc="albedo of the diffuse reflector", bands=True)
    absorption: str = static("product", choices=ABSORPTION_FORMS,
                             doc="f_1 absorption: Eq. 3.6 as printed, or the Beer double pass")
    underside: str = static("top", choices=UNDERSIDE_MODES,
                            doc="film reflectance from below: top-side R (D14) or Airy from eta2")
    color: str = static("rgb3", choices=spectral.COLOR_MODES, doc="output bands: rgb3, cie or spectral")
    wavelengths: tuple = static(spectral.RGB_WAVELENGTHS, convert=spectral.wavelengths_tuple,
                                doc="wavelengths (nm) of the 'spectral' colour mode")
    n_nodes: int = static(48, convert=integer(8, 1024), doc="Gauss-Legendre nodes of the Nyström solve")

    def _validate(self):
        n_wl = spectral.band_wavelengths_np(self.color, self.wavelengths).size
        for name in ("kd", "sigma_a"):
            v = np.atleast_1d(np.asarray(getattr(self, name)))
            if v.shape[-1] not in (1, n_wl):
                raise ValueError(
                    f"snake.Params.{name} has {v.shape[-1]} values on its trailing (wavelength) axis; "
                    f"color={self.color!r} computes on {n_wl} wavelengths: give a scalar or {n_wl} values")


# --------------------------------------------------------------------------------------
# building blocks


def _wavelengths(p: Params):
    return spectral.band_wavelengths(p.color, p.wavelengths)


def _out(p: Params, x):
    """Spectral values on the computation's wavelengths -> the output bands."""
    return spectral.to_bands(x, p.color, p.wavelengths)


def _scal(x, extra: int):
    """A scalar (per-direction) parameter with ``extra`` trailing singleton axes."""
    x = jnp.asarray(x)
    return x.reshape(x.shape + (1,) * extra)


def _band(x, extra: int):
    """A bands parameter (trailing wavelength axis) with ``extra`` more trailing axes."""
    x = as_bands(x)
    return x.reshape(x.shape + (1,) * extra)


_FILM = ("thickness", "eta0", "eta1", "eta2")


def _film_R(p: Params, mu, wl, extra: int, side: str):
    """Unpolarised film reflectance at cosine ``mu`` (aligned with ``wl``).

    ``extra``: number of trailing axes of mu/wl beyond the parameters' own shape.
    ``side="top"``: light from the eta0 side; ``"under"``: the underside per ``p.underside``.
    """
    d, e0, e1, e2 = (_scal(getattr(p, n), extra) for n in _FILM)
    if side == "under" and p.underside == "airy":
        e0, e2 = e2, e0
    # rounding puts R up to ~1e-15 above 1 under total internal reflection: keep T = 1 - R >= 0
    return jnp.clip(airy(mu, wl, d, e0, e1, e2).R, 0.0, 1.0)


def _film_Rs(p: Params, wl, requests):
    """Film reflectances for several cosine arrays, in as few ``airy`` calls as possible.

    ``requests``: ``(mu, side, extra)`` with ``extra`` = 1 for per-direction cosines (shape S,
    result S + (L,)) or 2 for the nodes (shape P + (n,), result P + (L, n)). With scalar film
    parameters (the usual case) all cosines of one side go through one call, which keeps
    the compiled program small (each traced ``airy`` costs ~0.5 s of XLA compile time).
    """
    out = [None] * len(requests)
    groups: dict[str, list[int]] = {}
    for i, (_, side, _) in enumerate(requests):
        eff = "top" if side == "top" or p.underside == "top" else "under"
        groups.setdefault(eff, []).append(i)
    scalar = all(jnp.ndim(getattr(p, n)) == 0 for n in _FILM)
    for eff, idx in groups.items():
        if scalar:
            flat = [jnp.reshape(requests[i][0], (-1,)) for i in idx]
            R = _film_R(p, jnp.concatenate(flat)[:, None], wl, 0, eff)  # (N, L)
            start = 0
            for i, f in zip(idx, flat):
                mu, _, extra = requests[i]
                r = R[start:start + f.shape[0]].reshape(jnp.shape(mu) + (wl.shape[0],))
                out[i] = jnp.swapaxes(r, -1, -2) if extra == 2 else r
                start += f.shape[0]
        else:
            for i in idx:
                mu, _, extra = requests[i]
                r = _film_R(p, jnp.asarray(mu)[..., None], wl, extra, eff)
                out[i] = jnp.swapaxes(r, -1, -2) if extra == 2 else r
    return out


def _safe_mu(mu):
    """Cosines <= 0 replaced by 1 (the caller masks them) and clipped to 1."""
    return jnp.where(mu > 0, jnp.where(mu > 1.0, 1.0, mu), 1.0)  # (minimum would halve d/dmu at 1)


def _tiny(dtype):
    # smallest cosine product kept in f_1's exponent: its square stays a normal number,
    # so d/dmu of tau / mu stays finite (and exp(-tau / tiny) = 0 for tau > 0 anyway)
    return float(np.sqrt(np.finfo(dtype).tiny)) * 4.0


def _f1(absorption: str, kd, tau, mu_a, mu_b):
    """Padrón Eq. 3.6 (or the Beer double pass) for positive cosines; everything broadcasts."""
    dt = jnp.result_type(mu_a, mu_b, float)
    t = _tiny(dt)
    if absorption == "product":
        x = tau / jnp.maximum(mu_a * mu_b, t)
    else:
        x = tau * (1.0 / jnp.maximum(mu_a, t) + 1.0 / jnp.maximum(mu_b, t))
    return kd / jnp.pi * jnp.exp(-x)


def _split(p: Params):
    """mu_c, the cosine below which the underside reflectance is total (0 if it never is).

    Light from a medium a through the film into a medium c is totally reflected for
    mu < mu_c = sqrt(1 - (c / a)^2) when c < a: R = 1 there whatever the film (the film's
    own TIR is frustrated, and R is analytic in q_1^2, so it has no kink of its own), and
    R - 1 ~ sqrt(mu - mu_c) above. a = eta_0, c = eta_2 for the top-side R (``"top"``);
    a = eta_2, c = eta_0 for ``"airy"``. mu_c is continuous in the indices (-> 0 as c -> a).
    """
    if p.underside == "airy":
        a, c = jnp.asarray(p.eta2), jnp.asarray(p.eta0)
    else:
        a, c = jnp.asarray(p.eta0), jnp.asarray(p.eta2)
    kink = c < a
    ratio = jnp.where(kink, c / jnp.where(kink, a, 1.0), 1.0)
    s2 = 1.0 - ratio * ratio
    pos = s2 > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, s2, 1.0)), 0.0)


def _nodes(p: Params):
    """Composite Gauss-Legendre rule for [0, 1] with a panel edge at the TIR kink: (mu, w), P + (n,).

    With s = mu_c (:func:`_split`): n // 4 nodes on [0, s] (R = 1 there; linear map) and the
    rest on [s, 1] through mu = s + (1 - s) phi(t), phi(t) = t^2 (2 - t) (phi'(0) = 0, so
    sqrt(mu - s) = sqrt(1 - s) t sqrt(2 - t) is smooth in t; phi'(1) = 1 keeps the nodes
    spread up to mu = 1). The rule is continuous in s and s is continuous in the indices,
    so f_d has no jump where a kink appears (eta_2 -> eta_0): gradients and finite
    differences agree there. Without a kink (s = 0) the first panel has zero weight (its
    nodes sit at mu = 0): the price of that continuity is n // 4 idle nodes.
    """
    n1 = p.n_nodes // 4
    n2 = p.n_nodes - n1
    dt = jnp.result_type(float)
    x1, w1 = (jnp.asarray(v, dt) for v in gauss_legendre(n1, 0.0, 1.0))
    x2, w2 = (jnp.asarray(v, dt) for v in gauss_legendre(n2, 0.0, 1.0))
    phi, dphi = x2 * x2 * (2.0 - x2), x2 * (4.0 - 3.0 * x2)
    s = _split(p)[..., None]
    lead = s.shape[:-1]
    parts = [(s * x1, s * w1), (s + (1.0 - s) * phi, (1.0 - s) * dphi * w2)]
    mu = jnp.concatenate([jnp.broadcast_to(a, lead + a.shape[-1:]) for a, _ in parts], axis=-1)
    w = jnp.concatenate([jnp.broadcast_to(b, lead + b.shape[-1:]) for _, b in parts], axis=-1)
    return mu, w


def _solve(p: Params, directions=()):
    """Nyström solve, and the film reflectances R(mu) of ``directions``.

    ``directions``: ``(mu, side)`` pairs of per-direction cosines (shape S) whose R (side
    "top" or "under") is needed too (computed in the same ``airy`` call as the nodes').
    Returns ``(mu_k, kd, tau, M, Q, wl), [R ...]`` with the parameters' leading shape P:
    mu_k P + (1, n), kd/tau P + (L|1, 1) (to broadcast against (..., L, n)),
    M P + (L, n, n) symmetric, Q P + (L, n) the albedo vector: A_d(mu) = T(mu) u(mu) . Q,
    and each R of shape S + (L,).
    """
    wl = _wavelengths(p)
    mu, w = _nodes(p)  # P + (n,)
    n = mu.shape[-1]
    kd = _band(p.kd, 1)  # P + (L|1, 1)
    tau = _band(p.sigma_a, 1) * _scal(p.depth, 2)  # P + (L|1, 1)
    mu_r = mu[..., None, :]  # P + (1, n), aligned with (L, n)
    w_r = w[..., None, :]
    Rs = _film_Rs(p, wl, [(mu, "under", 2)] + [(m, side, 1) for m, side in directions])
    R_u = Rs[0]  # P + (L, n)
    f1 = _f1(p.absorption, kd[..., None], tau[..., None], mu_r[..., :, None], mu_r[..., None, :])  # P + (L, n, n)
    shape = jnp.broadcast_shapes(f1.shape, R_u.shape[:-1] + (n, n))
    f1 = jnp.broadcast_to(f1, shape)
    D = 2.0 * jnp.pi * w_r * mu_r * R_u  # P + (L, n)
    D = jnp.broadcast_to(D, shape[:-1])
    eye = jnp.eye(n, dtype=f1.dtype)
    A = eye - f1 * D[..., None, :]
    # I - K is diagonally dominant (row sums of K <= albedo x max R < 1); the plain-XLA solve
    # avoids a LAPACK custom call that deadlocked vmapped multi-start fits (core.linalg)
    M = D[..., :, None] * solve_diagonally_dominant(A, jnp.broadcast_to(eye, shape))
    M = 0.5 * (M + jnp.swapaxes(M, -1, -2))
    # albedo: A_d(mu_i) = T(mu_i) sum_j c_j F(mu_i, mu_j), c_j = 2 pi w_j mu_j T_u(mu_j),
    # F(mu_i, mu_j) = u_j(mu_i) + (u(mu_i)^T M f1)_j  =>  Q = c + M f1 c
    c = 2.0 * jnp.pi * w_r * mu_r * (1.0 - R_u)
    c = jnp.broadcast_to(c, shape[:-1])
    Q = c + jnp.einsum("...jk,...kl,...l->...j", M, f1, c)
    return (mu_r, kd, tau, M, Q, wl), Rs[1:]


def _u(p: Params, kd, tau, mu_nodes, mu, n_bands: int):
    """u(mu)_k = f_1(mu, mu_k): shape S + (L, n) for mu of shape S."""
    u = _f1(p.absorption, kd, tau, mu[..., None, None], mu_nodes)
    return jnp.broadcast_to(u, u.shape[:-2] + (n_bands, u.shape[-1]))


def _quad_form(ui, M, uo):
    """sum_jk ui_j M_jk uo_k over the last axes, broadcasting the leading ones."""
    if M.ndim == 3:  # parameters without leading axes: one shared matrix per band
        v = jnp.einsum("ljk,...lk->...lj", M, uo)
    else:
        v = jnp.einsum("...ljk,...lk->...lj", M, uo)
    return jnp.sum(ui * v, axis=-1)


# --------------------------------------------------------------------------------------
# kernels


def _components_spectral(p: Params, wi: Vec3, wo: Vec3):
    """(f_d(wi, wo), R(mu_i), A_d(mu_i)) on the computation's wavelengths: one solve, one airy."""
    ok_i = wi.z > 0
    ok = ok_i & (wo.z > 0)
    mi, mo = _safe_mu(wi.z), _safe_mu(wo.z)
    (mu_k, kd, tau, M, Q, wl), (R_i, R_o) = _solve(p, [(mi, "top"), (mo, "under")])
    L = wl.shape[0]
    ui = _u(p, kd, tau, mu_k, mi, L)
    uo = _u(p, kd, tau, mu_k, mo, L)
    F = _f1(p.absorption, kd[..., 0], tau[..., 0], with_bands(mi), with_bands(mo)) + _quad_form(ui, M, uo)
    f = (1.0 - R_i) * F * (1.0 - R_o)
    A = (1.0 - R_i) * jnp.sum(ui * Q, axis=-1)
    zero = lambda ok, x: jnp.where(with_bands(ok), x, 0.0)  # noqa: E731
    return zero(ok, f), zero(ok_i, R_i), zero(ok_i, A)


def _components(p: Params, wi: Vec3, wo: Vec3):
    return tuple(_out(p, x) for x in _components_spectral(p, wi, wo))


def _eval(p: Params, wi: Vec3, wo: Vec3):
    return _components(p, wi, wo)[0]


def _specular(p: Params, wi: Vec3):
    ok = wi.z > 0
    R = _film_R(p, with_bands(_safe_mu(wi.z)), _wavelengths(p), 1, "top")
    return _out(p, jnp.where(with_bands(ok), R, 0.0))


def _albedo(p: Params, wi: Vec3):
    return _components(p, wi, wi)[2]


def _pdf(p: Params, wi: Vec3, wo: Vec3):
    ok = (wi.z > 0) & (wo.z > 0)
    return jnp.where(ok, warp.square_to_cosine_hemisphere_pdf(wo), 0.0)


def _sample(p: Params, wi: Vec3, u):
    shape = jnp.shape(wi.z)
    u1, u2 = uniforms(u, shape, 2)
    wo = warp.square_to_cosine_hemisphere(u1, u2)
    ok = (wi.z > 0) & (wo.z > 0)
    pdf = jnp.where(ok, warp.square_to_cosine_hemisphere_pdf(wo), 0.0)
    # weight = f_d cos_o / pdf = pi f_d
    weight = jnp.where(with_bands(ok), jnp.pi * _eval(p, wi, wo), 0.0)
    return wo, weight, pdf


def _sample_full(p: Params, wi: Vec3, u):
    """Mirror lobe with probability mean(R) / (mean(R) + mean(A_d)), else cosine-weighted."""
    shape = jnp.shape(wi.z)
    u0, u1, u2 = uniforms(u, shape, 3)
    ok = wi.z > 0
    wd = warp.square_to_cosine_hemisphere(u1, u2)
    f, R, A = _components(p, wi, wd)
    r, a = jnp.mean(R, axis=-1), jnp.mean(A, axis=-1)
    tot = r + a
    pos = tot > 0
    p_spec = jnp.where(pos, r / jnp.where(pos, tot, 1.0), 0.0)
    is_delta = ok & (u0 < p_spec)
    mirror = Vec3(-wi.x, -wi.y, wi.z)
    wo = Vec3(*(jnp.where(is_delta, m, d) for m, d in zip(mirror, wd)))
    ok_d = ok & ~is_delta & (wd.z > 0) & (p_spec < 1)
    w_spec = R / with_bands(jnp.where(is_delta, p_spec, 1.0))
    w_diff = jnp.pi * f / with_bands(jnp.where(ok_d, 1.0 - p_spec, 1.0))
    weight = jnp.where(with_bands(is_delta), w_spec, jnp.where(with_bands(ok_d), w_diff, 0.0))
    return wo, weight, is_delta


def _eval_mc(p: Params, wi: Vec3, wo: Vec3, key, n_paths: int, max_bounces: int, roulette: bool):
    """Position-free random walk between f_1 and the film's underside (see :func:`eval_mc`)."""
    wl = _wavelengths(p)
    ok = (wi.z > 0) & (wo.z > 0)
    mi, mo = _safe_mu(wi.z), _safe_mu(wo.z)
    kd = _band(p.kd, 0)
    tau = _band(p.sigma_a, 0) * _scal(p.depth, 1)
    R_i, R_o = _film_Rs(p, wl, [(mi, "top", 1), (mo, "under", 1)])
    T_in, T_out = 1.0 - R_i, 1.0 - R_o  # S + (L,)
    base = jnp.broadcast_shapes(jnp.shape(mi), jnp.shape(mo), T_in.shape[:-1], T_out.shape[:-1],
                                kd.shape[:-1], tau.shape[:-1])
    L = wl.shape[0]
    shape = base + (n_paths,)
    kd, tau = kd[..., None, :], tau[..., None, :]  # broadcast against shape + (L,)
    mo_p = with_bands(jnp.broadcast_to(mo[..., None], shape))
    mu0 = jnp.broadcast_to(mi[..., None], shape)
    beta0 = jnp.broadcast_to(T_in[..., None, :], shape + (L,))
    acc0 = jnp.zeros(shape + (L,), beta0.dtype)

    def step(carry, k):
        mu, beta, acc = carry
        # next-event estimation towards wo at this bottom vertex
        acc = acc + beta * _f1(p.absorption, kd, tau, with_bands(mu), mo_p)
        # bounce: cosine-weighted mu' (pdf mu'/pi), weight f_1 mu' / pdf = pi f_1
        k1, k2 = jax.random.split(k)
        u = jax.random.uniform(k1, shape, beta.dtype)
        mu_new = jnp.sqrt(1.0 - u)  # in (0, 1]
        mu_new = jnp.where(mu_new > 0, mu_new, 1.0)
        R = _film_R(p, with_bands(mu_new), wl, 1, "under")
        beta = beta * jnp.pi * _f1(p.absorption, kd, tau, with_bands(mu), with_bands(mu_new))
        if roulette:  # survive the underside with probability mean_band(R), weight R / q
            q = jnp.mean(R, axis=-1)
            alive = jax.random.uniform(k2, shape, beta.dtype) < q
            beta = jnp.where(with_bands(alive), beta * R / with_bands(jnp.where(alive, q, 1.0)), 0.0)
        else:  # the underside reflection as a weight
            beta = beta * R
        return (mu_new, beta, acc), None

    keys = jax.random.split(key, max_bounces)
    (_, _, acc), _ = jax.lax.scan(step, (mu0, beta0, acc0), keys)
    x = acc * T_out[..., None, :]  # per-path estimates, base + (n_paths, L)
    x = jnp.where(with_bands(ok[..., None]), x, 0.0)
    x = _out(p, x)
    est = jnp.mean(x, axis=-2)
    se = jnp.std(x, axis=-2, ddof=1) / math.sqrt(n_paths) if n_paths > 1 else jnp.zeros_like(est)
    return est, se


# --------------------------------------------------------------------------------------
# public functions

eval = boundary(_eval, Params)
pdf = boundary(_pdf, Params)
sample = boundary(_sample, Params)
specular = boundary(_specular, Params)
specular.__doc__ = """Weight of the mirror (delta) lobe, R(mu_i) per band: the spec's ``delta_weight``.

``eval`` excludes it. 0 for mu_i <= 0."""
albedo = boundary(_albedo, Params)
albedo.__doc__ = """Directional albedo of the non-delta part, 2 pi int f_d(mu_i, mu_o) mu_o dmu_o (bands).

Quadrature over the Nyström nodes with the Nyström-interpolated F; deterministic and
differentiable. With k_d = 1, sigma_a = 0: specular + albedo = 1 to rounding."""
components = boundary(_components, Params)
components.__doc__ = """``(f_d(wi, wo), delta_weight(wi), albedo(wi))`` from one Nyström solve (bands each).

What a renderer needs at a vertex: the non-delta value (= ``eval``), the mirror lobe's
weight R(mu_i) (= ``specular``) and the non-delta albedo (= ``albedo``, for lobe selection),
with one solve and one film evaluation (one compiled program)."""
_sample_full_b = boundary(_sample_full, Params)
_eval_mc_b = boundary(_eval_mc, Params, static_argnames=("n_paths", "max_bounces", "roulette"))


def sample_full(params: Params, wi: Vec3, u_or_key):
    """Sample the whole BSDF (mirror lobe + f_d) for a path tracer: ``(wo, weight, is_delta)``.

    The mirror direction is chosen with probability P = mean(R) / (mean(R) + mean(A_d))
    (band means of :func:`specular` and :func:`albedo`, spec §2.1.4), with weight R / P;
    otherwise a cosine-weighted direction with weight pi f_d / (1 - P). ``u_or_key``: a PRNG
    key or 3 uniform arrays (lobe choice, then the two of the cosine warp).
    """
    return _sample_full_b(params, wi, u_or_key)


def eval_mc(params: Params, wi: Vec3, wo: Vec3, key, n_paths: int = 4096, max_bounces: int = 64,
            roulette: bool = False):
    """Monte Carlo estimate of the non-delta part f_d and its standard error (bands).

    An independent, position-free random walk (the PFMC of the thesis reduced to this
    two-layer stack): the path enters through the film with the deterministic weight
    T(mu_i) and travels straight down at mu_i; at every bottom vertex (arriving at mu)

    * next-event estimation towards wo: adds weight f_1(mu, mu_o) T_u(mu_o);
    * bounce: mu' cosine-weighted (pdf mu'/pi in solid angle), weight *= pi f_1(mu, mu');
    * film underside: weight *= R_u(mu') (``roulette=False``), or the path survives with
      probability q = mean_band R_u(mu') and weight *= R_u / q (``roulette=True``; dead paths
      carry weight 0, the alive mask); then it goes down again at mu'.

    ``lax.scan`` over ``max_bounces`` vertices (the tail beyond them is dropped: bias
    <= the mean remaining weight, negligible for the 64 default unless R_u ~ 1 and
    k_d ~ 1 with sigma_a = 0). Returns ``(estimate, stderr)`` of shape ``wi.shape + (bands,)``;
    stderr = sample std (ddof 1) / sqrt(n_paths) over the per-path estimates. The same
    ``key`` gives the same numbers (common random numbers: the directions do not depend
    on the parameters, so gradients of the estimate are consistent). ``key``: a PRNG key
    or an int seed.
    """
    n_paths = check_int("snake.eval_mc: n_paths", n_paths, 2)
    max_bounces = check_int("snake.eval_mc: max_bounces", max_bounces, 1)
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        key = jax.random.key(int(key))
    elif not is_prng_key(key):
        raise ValueError(f"snake.eval_mc: key = {key!r} must be a PRNG key or an int seed")
    return _eval_mc_b(params, wi, wo, key, n_paths=n_paths, max_bounces=max_bounces, roulette=bool(roulette))


PRESETS = {
    # Padrón Table 3.1 [T:480-489]: eta_0 = 1, eta_1 = 1.53; the table prints no delta_0, eta_2 or
    # k_d: delta_0 = 900 nm and eta_2 = 1 from Padrón Fig. 3.6(c), sigma_a = 0.7, delta_1 = 2 and
    # k_d = 0 from Padrón Sec. 3.5.2 (so f_d = 0: Q-S5)
    "table_3_1": Params(thickness=900.0, eta0=1.0, eta1=1.53, eta2=1.0, sigma_a=0.7, depth=2.0, kd=0.0),
    # Padrón Fig. 3.5 defaults [T:540, 547] (rows vary delta_0, columns eta_2; values not printed)
    "fig_3_5": Params(thickness=900.0, eta0=1.0, eta1=1.56, eta2=1.0, sigma_a=0.7, depth=2.0, kd=0.0),
    # Padrón Fig. 3.6(a): the plain diffuse baseline k_d = 0.3, written as a film-less stack
    # (delta_0 = 0, eta_0 = eta_1 = eta_2 = 1 => R = 0, T = 1; sigma_a = 0 => f = k_d / pi)
    "fig_3_6a_diffuse": Params(thickness=0.0, eta0=1.0, eta1=1.0, eta2=1.0, sigma_a=0.0, depth=2.0, kd=0.3),
    # Padrón Fig. 3.6(d) [T:550]: the film (smooth here; rough in the figure) with absorption and k_d = 0
    "fig_3_6d": Params(thickness=900.0, eta0=1.0, eta1=1.56, eta2=1.0, sigma_a=0.7, depth=2.0, kd=0.0),
    # the configuration of the spec's M26 check table (= the defaults)
    "spec_m26_check": Params(),
}

MODEL = Model(
    name="snake",
    kind="bsdf",
    Params=Params,
    eval=eval,
    sample=sample,
    pdf=pdf,
    summary="snake skin: smooth Airy thin film over an absorbing diffuse layer (Nyström-solved, non-delta part)",
    source="Padrón Griffé 2025, Ch. 3 (Padrón-Griffé et al. CEIG 2023)",
    reciprocal=True,
    presets=PRESETS,
)

__all__ = ["Params", "eval", "pdf", "sample", "sample_full", "components", "specular", "albedo", "eval_mc",
           "MODEL", "PRESETS", "ABSORPTION_FORMS", "UNDERSIDE_MODES"]
