"""Deterministic, differentiable transport in the cosmetic medium: discrete ordinates in the
polar cosine, Fourier modes in azimuth, adding-doubling across depth (Padrón 2025 Ch. 4,
Eqs. 4.3-4.10; issue 25).

What it solves: a stack of index-matched, laterally infinite slabs of the cosmetic medium
(:mod:`.medium`: diffusers with the two-lobe HG phase function + SGGX platelets, with
direction-dependent extinction and albedo), each with its own thickness (base mean free
paths), over a base BSDF (a Lambertian albedo, or any library model with a deterministic
``eval``), optionally under a smooth dielectric interface (host index ``eta``: Fresnel
reflection and refraction at the top, total internal reflection included). It returns the
BRDF f(wi, wo) [1/sr] at arbitrary directions, the quantity the random walk
(:func:`.random_walk.walk`) estimates; that walk is its reference.

Method.

- **The azimuth.** A platelet tilt theta_p breaks the symmetry about the normal. The solver
  works with the *azimuth mixture* of the medium: its extinction and scattering coefficient
  averaged over rotations of the platelet population about the normal (``n_rot`` rotations;
  for theta_p = 0 the mixture *is* the medium). The mixture is symmetric about the normal and
  under z -> -z, so the kernels split into independent Fourier modes cos(m dphi) and a slab
  has one reflection and one transmission kernel. Single scattering — the sharp part, the
  platelets' highlight — is computed exactly for the oriented medium at the query directions
  (``azimuth="fixed"``) or exactly averaged over sample rotations (``"averaged"``, the
  in-plane measurement of an unoriented sample, decision D4). The multiply scattered
  remainder comes from the mixture, plus (``tilt``, default on) the difference between the
  oriented medium and its mixture from a coarse full-azimuth solve (:mod:`.ordinates_tilt`;
  docs/cosmetics.md). At theta_p = 0 the mixture is the medium and the correction vanishes.
- **The kernels.** sigma_s f of the mixture (:func:`.medium.scattering_coefficient`) is
  evaluated on the node cosines x an azimuth grid of ``n_az`` points, averaged over the
  rotations and reduced to ``n_modes`` cosine modes by a discrete Fourier sum; the
  extinction sigma(mu) likewise.
- **Depth.** Each slab starts at thickness t 2^-K (K = ``n_doublings``) from the exact single
  scattering of the mixture with direction-dependent extinction,
  ``R0 = S_R t0 phi(t0 (s_o/mu_o + s_i/mu_i)) / (mu_o mu_i)``,
  ``T0 = S_T exp(-t0 s_o/mu_o) t0 phi(t0 (s_i/mu_i - s_o/mu_o)) / (mu_o mu_i)``
  (phi(x) = (1 - e^-x)/x), is doubled K times, then slabs, base and interface are combined by
  the adding equations (:mod:`.kernel_ops`; van de Hulst 1980 Ch. 5, 14). Quadrature: ``n_nodes``
  Gauss-Legendre cosines per hemisphere.
- **Queries.** f(wi, wo) = exact single scattering (every layer, attenuated by the layers
  above, plus the base seen through the stack) + the multiply scattered remainder, whose
  Fourier kernels are interpolated from the nodes to the query cosines (barycentric
  Lagrange on the Gauss nodes) and summed over the modes at the query's azimuth difference.
  The cost of a query is O(n_modes n_nodes^2) after one solve per parameter set, whatever
  the number of queries. :func:`fourier_kernels` instead puts given cosines on the node list
  with zero quadrature weight (no interpolation error; the accuracy reference of the
  interpolation, measured in tests/layered/test_ordinates.py).
- **The interface** (eta != 1): directions refract into the host (Snell), radiance enters
  and leaves with the Fresnel transmittances and the 1/eta^2 radiance factor,
  f = (1 - F_i)(1 - F_o) f_inside / eta^2, and light reflected back down by the interface
  from inside (Fresnel, total internal reflection beyond the critical angle) is added with a
  specular (diagonal) operator: R_inside = (I - R C F)^-1 R.

| setting     | default | meaning                                                               |
|-------------|---------|-----------------------------------------------------------------------|
| n_nodes     | 24      | Gauss-Legendre polar cosines per hemisphere                            |
| n_modes     | 24      | azimuthal Fourier modes of the multiply scattered light              |
| n_az        | 192     | azimuth samples of a kernel before the Fourier sum (>= 2 n_modes)    |
| n_rot       | 16      | rotations of a tilted platelet population in the mixture / averages  |
| n_doublings | 24      | doublings of the starting layer (t0 = t 2^-K)                        |
| n_rot_single | 128    | sample rotations of the exact single scattering ("averaged")         |
| tilt        | True    | add the oriented-minus-mixture correction (:mod:`.ordinates_tilt`)   |
| tilt_mu, tilt_phi | 6, 12 | the correction's coarse grid (cosines, azimuths; tilt_phi even)  |

Accuracy of the defaults against the walk and against finer settings: docs/cosmetics.md.
Directions at or below the horizon give 0 (finite gradients).
"""

from __future__ import annotations

import math
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..core.model import with_bands
from ..core.quadrature import gauss_legendre
from ..core.special import atan2, safe_sqrt
from ..core.vec import Vec3
from ..optics.fresnel import fresnel_dielectric, interface_amplitudes
from . import medium as med
from . import ordinates_tilt
from .kernel_ops import add, doubled_slab, left, resolvent, right


ALPHA_GRID_SCALE = 2.0  # resolvable platelet roughness x n_nodes (resolvable_alpha)


class Settings(NamedTuple):
    """Discretisation of the solver (module table); hashable, a static argument."""

    n_nodes: int = 24
    n_modes: int = 24
    n_az: int = 192
    n_rot: int = 16
    n_doublings: int = 24
    n_rot_single: int = 128
    tilt: bool = True
    tilt_mu: int = 6
    tilt_phi: int = 12

    def check(self):
        for name, lo in (("n_nodes", 2), ("n_modes", 1), ("n_rot", 1), ("n_rot_single", 1), ("n_doublings", 0),
                         ("tilt_mu", 2), ("tilt_phi", 4)):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < lo:
                raise ValueError(f"ordinates: {name} = {v!r} must be an integer >= {lo}")
        if not isinstance(self.n_az, (int, np.integer)) or self.n_az < 2 * self.n_modes:
            raise ValueError(f"ordinates: n_az = {self.n_az!r} must be an integer >= 2 n_modes = {2 * self.n_modes}")
        if self.tilt_phi % 2:
            raise ValueError(f"ordinates: tilt_phi = {self.tilt_phi} must be even (the grid pairs phi with phi + pi)")
        return self


# ------------------------------------------------------------------------------------
# directions


def _dirs(mu, phi_, up: bool) -> Vec3:
    """Unit vectors at polar cosine ``mu`` (> 0) and azimuth ``phi_``, upward or downward."""
    return ordinates_tilt.direction(mu, phi_, up)


def _rotations(n_rot: int):
    return (np.arange(n_rot) + 0.5) * (2.0 * np.pi / n_rot)


def _layer(media, k):
    return med.Params(**{n: getattr(media, n)[k] for n in med.FIELDS})


# ------------------------------------------------------------------------------------
# the mixture's kernels on the nodes


def resolvable_alpha(alpha, s: Settings):
    """The platelet roughness of the multiply scattered kernels: alpha where the node grid
    resolves the flakes' lobe, raised smoothly to ~``ALPHA_GRID_SCALE / n_nodes`` below
    (``(alpha^4 + alpha_min^4)^(1/4)``). A lobe much narrower than the node spacing is
    point-sampled as noise (negative radiances at alpha = 0.002); blurred to the grid it keeps
    its energy, and later events (diffusers) blur the angular detail it loses anyway. The
    single scattering, the sharp highlight, always uses the true alpha."""
    a_min = ALPHA_GRID_SCALE / s.n_nodes
    return jnp.sqrt(jnp.sqrt(alpha**4 + a_min**4))


def _fourier_table(s: Settings, dtype):
    """(M, A): cos(m dphi_a) / n_az, the discrete Fourier sum of a kernel sampled at n_az azimuths."""
    a = (2.0 * np.pi / s.n_az) * np.arange(s.n_az)
    return jnp.asarray(np.cos(np.arange(s.n_modes)[:, None] * a[None, :]) / s.n_az, dtype)


def _mixture_kernels(m, mu, s: Settings):
    """Fourier modes of sigma_s f of the azimuth mixture, ``(S_R, S_T)`` of shape (B, M, N, N)
    [out, in] in the propagation convention (light arrives travelling down at mu_in, leaves
    travelling up (R) or down (T) at mu_out), and the mixture's extinction sigma(mu) (N,)."""
    m = m.replace(alpha=resolvable_alpha(m.alpha, s))
    cosm = _fourier_table(s, mu.dtype)
    gam = _rotations(s.n_rot)[:, None, None, None]
    dphi = (2.0 * np.pi / s.n_az) * np.arange(s.n_az)[None, :, None, None]
    mo = mu[None, None, :, None]
    mi = mu[None, None, None, :]

    # sigma_s f = Lambda_d c_d f_d + Lambda_p (1 - c_d) D / 4 (medium.scattering_coefficient),
    # split so that each colourless part is evaluated once: the diffusers' phase function is
    # symmetric about the normal (one rotation), the platelets' D is averaged over them. R and T
    # (light leaving up / down: the sign of the outgoing z) are one evaluation along a leading
    # axis of 2, not two: half the compiled code
    up = np.array([1.0, -1.0])[:, None, None, None]
    d_in = _dirs(mi[0], 0.0, up=False)
    hg = med.diffuser_phase(m, Vec3(-d_in.x, -d_in.y, -d_in.z), ordinates_tilt.direction(mo[0], dphi[0], up))
    # each pair centred on its rotation (azimuths gam -+ dphi/2): the rotation set is symmetric under
    # the platelets' mirror, so the discrete average is even in dphi and reciprocal, as the continuous
    # one is (pairs starting at gam broke reciprocity by up to 2e-3 at theta_p = 52 deg, n_rot = 16)
    d_in = _dirs(mi, gam - 0.5 * dphi, up=False)
    D = jnp.mean(med.platelet_D(m, Vec3(-d_in.x, -d_in.y, -d_in.z),
                                ordinates_tilt.direction(mo, gam + 0.5 * dphi, up[..., None])), axis=1)  # (2, A, N, N)
    hg_m = jnp.einsum("ma,uaoi->umoi", cosm, hg)
    D_m = jnp.einsum("ma,uaoi->umoi", cosm, D)
    ad = jnp.asarray(m.albedo_d)[:, None, None, None, None]
    ap = jnp.asarray(m.albedo_p)[:, None, None, None, None]
    S = ad * m.c_d * hg_m[None] + ap * (1.0 - m.c_d) * 0.25 * D_m[None]  # (B, 2, M, N, N)

    sig = jnp.mean(med.extinction(m, _dirs(mu[None, :], _rotations(s.n_rot)[:, None], up=True)), axis=0)
    return S[:, 0], S[:, 1], sig


def _single_nodes(SR, sig, t, mu):
    """Single scattering of one slab over nothing on the nodes (modes), the exact closed form."""
    a = sig / mu
    x = a[:, None] + a[None, :]
    return SR * (-jnp.expm1(-t * x) / (x * mu[:, None] * mu[None, :]))


def _base_modes(base, mu, s: Settings, dtype):
    """Fourier modes (B, M, N, N) of the base BSDF on the nodes, propagation convention."""
    kind, value = base
    N = mu.shape[0]
    if kind == "lambert":
        rho = jnp.atleast_1d(jnp.asarray(value, dtype))
        return jnp.zeros((rho.shape[0], s.n_modes, N, N), dtype).at[:, 0].set((rho / np.pi)[:, None, None])
    model, params = value
    dphi = (2.0 * np.pi / s.n_az) * np.arange(s.n_az)[:, None, None]
    wi = _dirs(mu[None, None, :], np.pi, up=True)  # away: azimuth pi (the light travels along phi = 0)
    wo = _dirs(mu[None, :, None], dphi, up=True)
    shape = (s.n_az, N, N)
    wi = Vec3(*(jnp.broadcast_to(v, shape).ravel() for v in wi))
    wo = Vec3(*(jnp.broadcast_to(v, shape).ravel() for v in wo))
    f = jnp.asarray(model.eval.kernel(params, wi, wo), dtype)
    f = f.reshape(shape + ((f.shape[-1],) if f.ndim == 2 else (1,)))
    return jnp.einsum("ma,aoib->bmoi", _fourier_table(s, dtype), f)


class Solution(NamedTuple):
    """The multiply scattered Fourier kernels on the nodes (B, M, N, N), the node cosines, and
    the tilt correction on its coarse grid (:mod:`.ordinates_tilt`; None when switched off)."""

    ms: Any
    mu: Any
    tilt: Any = None


def _solve(media, thickness, base, eta, mu_x, s: Settings):
    """Total reflection kernels (B, M, N+q, N+q) inside the host (interface reflections
    included) and the single-scattering part the kernels contain, on nodes + zero-weight
    queries ``mu_x``."""
    n = s.n_nodes
    x, w = gauss_legendre(n, 0.0, 1.0)
    dtype = jnp.result_type(thickness)
    mu = jnp.concatenate([jnp.asarray(x, dtype), jnp.asarray(mu_x, dtype)])
    c = jnp.concatenate([jnp.asarray(2.0 * np.pi * x * w, dtype), jnp.zeros(jnp.shape(mu_x), dtype)])
    L = thickness.shape[0]
    stack, ss, above = None, 0.0, jnp.ones_like(mu)
    for k in range(L):
        SR, ST, sig = _mixture_kernels(_layer(media, k), mu, s)
        op = doubled_slab(SR, ST, sig, thickness[k], mu, c, n, s.n_doublings)
        ss = ss + above[:, None] * above[None, :] * _single_nodes(SR, sig, thickness[k], mu)
        above = above * op.e
        stack = op if stack is None else add(stack, op, c, n)
    Rb = _base_modes(base, mu, s, dtype)
    ss = ss + above[:, None] * above[None, :] * Rb
    W = resolvent(Rb, stack.Rs, c, n)
    R = stack.R + left(stack.e, stack.Ts, right(W, stack.e, stack.T, c, n), c, n)
    if eta is not None:
        W = _interface_weights(np.asarray(x), eta, dtype)
        diag = jnp.zeros_like(R[0, 0]).at[jnp.arange(n), jnp.arange(n)].set(W / (c[:n] * c[:n]))
        R = resolvent(R, diag, c, n)  # (I - R W)^-1 R: specular interface reflections from below
    return R, ss


def _interface_weights(nodes, eta, dtype, n_fine: int = 48):
    """Quadrature weights W_j = 2 pi int_0^1 F(mu) l_j(mu) mu dmu of the interface's internal
    reflection, F the Fresnel reflectance from inside, l_j the Lagrange polynomials of the
    nodes. With s = 1 - 1/eta^2 = mu_c^2 (mu_c the critical cosine): total internal reflection
    (F = 1) on mu < mu_c, integrated with mu = mu_c v; the partial reflection above it with
    mu^2 = s + (1 - s) t^2, which makes the outside cosine eta sqrt(1 - s) t linear in t and
    removes the square-root kink of F at mu_c, with a Gauss rule split at t = 4 mu_c, where F
    falls at eta -> 1. Both parts are smooth in t, so the rule is exact to rounding (checked
    against adaptive quadrature, eta - 1 from 1e-6 to 2; the plain Gauss rule c_j F(mu_j) is off
    by ~1 % for a Lambertian base under eta = 1.5 at 24 nodes).

    eta = 1 (no interface) is the lower end of the domain: there W = 0 and W rises as
    pi s (1 + 1/6) l_j(0), the 1 from total internal reflection and the 1/6 = int_0^inf
    (sqrt(1 + y) - sqrt(y))^4 dy from the partial reflection concentrated within ~mu_c of
    grazing (the leading order of F for eta -> 1, with mu^2 = s (1 + y)). Differentiating the
    rule at s = 0 gives the first term only, so the second's tangent is added there: the
    derivative at eta = 1 is the right derivative, 2 pi (7/6) l_j(0) per unit eta."""
    s = 1.0 - 1.0 / (eta * eta)
    mu_c = safe_sqrt(s)
    xf, wf = gauss_legendre(n_fine, 0.0, 1.0)
    xf, wf = jnp.asarray(xf, dtype), jnp.asarray(wf, dtype)
    t1 = jnp.minimum(4.0 * mu_c, 0.5)
    t = jnp.concatenate([t1 * xf, t1 + (1.0 - t1) * xf])
    wt = jnp.concatenate([t1 * wf, (1.0 - t1) * wf])
    mu = safe_sqrt(s + (1.0 - s) * t * t)
    # q = eta cos on each side: eta mu inside, the outside cosine eta sqrt(1 - s) t outside (at s = 0
    # the first part of the rule has t = mu = 0, and zero weights: the helper returns r = 0 there)
    rs, rp, _, _ = interface_amplitudes(eta * mu, eta * safe_sqrt(1.0 - s) * t, eta, 1.0)
    F = 0.5 * jnp.real(rs * jnp.conj(rs) + rp * jnp.conj(rp))
    x = jnp.concatenate([mu_c * xf, mu])
    w = jnp.concatenate([s * wf * xf, (1.0 - s) * wt * t * F])  # F mu dmu = F (1 - s) t dt
    W = 2.0 * np.pi * jnp.einsum("f,fj->j", w, _lagrange(x, nodes))
    grazing = np.pi / 6.0 * _lagrange(jnp.zeros((1,), dtype), nodes)[0]
    return W + jnp.where(s > 0, 0.0, (s - jax.lax.stop_gradient(s)) * grazing)


@partial(jax.jit, static_argnames=("s", "base_kind"))
def _solution(media, thickness, base_value, eta, s: Settings, base_kind: str):
    dtype = thickness.dtype
    R, ss = _solve(media, thickness, (base_kind, base_value), eta, jnp.zeros((0,), dtype), s)
    x, _ = gauss_legendre(s.n_nodes, 0.0, 1.0)
    tilt = None
    if s.tilt:
        xc, _ = gauss_legendre(s.tilt_mu, 0.0, 1.0)
        W = None if eta is None else _interface_weights(np.asarray(xc), eta, dtype)
        tilt, _ = ordinates_tilt.correction(media, thickness, partial(_base_grid, (base_kind, base_value)), W, dtype,
                                            s.tilt_mu, s.tilt_phi)
    return Solution(R - ss, jnp.asarray(x, dtype), tilt)


def _base_grid(base, mu, az):
    """The base BSDF (B, N, N) [out, in] between the directions of a full (mu, az) grid, light
    arriving travelling down along (mu, az), leaving up (propagation azimuths)."""
    kind, value = base
    N = mu.shape[0]
    if kind == "lambert":
        rho = jnp.atleast_1d(jnp.asarray(value, mu.dtype))
        return jnp.broadcast_to((rho / np.pi)[:, None, None], (rho.shape[0], N, N))
    model, params = value
    s = jnp.sqrt(1.0 - mu * mu)
    wi = Vec3(-s * jnp.cos(az), -s * jnp.sin(az), mu)  # away from the surface, back along the light
    wo = Vec3(s * jnp.cos(az), s * jnp.sin(az), mu)
    shape = (N, N)
    wi = Vec3(*(jnp.broadcast_to(v[None, :], shape).ravel() for v in wi))
    wo = Vec3(*(jnp.broadcast_to(v[:, None], shape).ravel() for v in wo))
    f = jnp.asarray(model.eval.kernel(params, wi, wo), mu.dtype)
    f = f.reshape(shape + ((f.shape[-1],) if f.ndim == 2 else (1,)))
    return jnp.moveaxis(f, -1, 0)


# ------------------------------------------------------------------------------------
# queries


def _lagrange(x, nodes):
    """Barycentric Lagrange weights (Q, n) of the polynomial through ``nodes`` at ``x``."""
    xn = np.asarray(nodes, np.float64)
    bw = 1.0 / np.array([np.prod(xn[j] - np.delete(xn, j)) for j in range(xn.size)])
    bw = bw / np.max(np.abs(bw))
    d = x[:, None] - jnp.asarray(xn, x.dtype)[None, :]
    hit = d == 0
    t = jnp.asarray(bw, x.dtype) / jnp.where(hit, 1.0, d)
    Lw = t / jnp.sum(t, axis=1, keepdims=True)
    return jnp.where(jnp.any(hit, axis=1, keepdims=True), hit.astype(x.dtype), Lw)


def _single_query(media, thickness, base, wi_in: Vec3, wo_in: Vec3, dtype):
    """Exact single scattering of the oriented stack + the base seen through it, at the
    refracted query directions (wi_in, wo_in pointing away, inside the host), (Q, B)."""
    mi, mo = wi_in.z, wo_in.z
    L = thickness.shape[0]
    total, ti, to = 0.0, jnp.ones_like(mi), jnp.ones_like(mo)
    for k in range(L):
        m = _layer(media, k)
        si, so = med.extinction(m, wi_in), med.extinction(m, wo_in)
        x = si / mi + so / mo
        layer = -jnp.expm1(-thickness[k] * x) / (si * mo + so * mi)  # / (x mi mo), finite at grazing
        total = total + with_bands(ti * to * layer) * med.scattering_coefficient(m, wi_in, wo_in)
        ti = ti * jnp.exp(-thickness[k] * si / mi)
        to = to * jnp.exp(-thickness[k] * so / mo)
    kind, value = base
    if kind == "lambert":
        fb = with_bands(jnp.ones_like(mi)) * jnp.atleast_1d(jnp.asarray(value, dtype)) / np.pi
    else:
        model, params = value
        fb = jnp.asarray(model.eval.kernel(params, wi_in, wo_in), dtype)
        fb = fb if fb.ndim == mi.ndim + 1 else fb[..., None]
    return total + with_bands(ti * to) * fb


@partial(jax.jit, static_argnames=("s", "base_kind", "averaged"))
def _brdf(media, thickness, base_value, eta, wi: Vec3, wo: Vec3, sol: Solution, s: Settings,
          base_kind: str, averaged: bool):
    dtype = thickness.dtype
    ok = (wi.z > 0) & (wo.z > 0)
    safe = lambda w: Vec3(jnp.where(ok, w.x, 0.0), jnp.where(ok, w.y, 0.0), jnp.where(ok, w.z, 1.0))  # noqa: E731
    wi, wo = safe(wi), safe(wo)
    if eta is None:
        wi_in, wo_in, factor = wi, wo, jnp.ones_like(wi.z)
    else:
        wi_in, Fi = _refract_in(wi, eta)
        wo_in, Fo = _refract_in(wo, eta)
        factor = (1.0 - Fi) * (1.0 - Fo) / (eta * eta)
    # multiply scattered part: interpolated modes, summed at the propagation azimuth difference
    nodes, _ = gauss_legendre(s.n_nodes, 0.0, 1.0)
    Li = _lagrange(wi_in.z, nodes)
    Lo = _lagrange(wo_in.z, nodes)
    # a smooth function on the sphere has modes (1 - mu^2)^(m/2) x a polynomial in mu: for odd m
    # the factor sqrt(1 - mu^2) of each side is taken out before the polynomial interpolation
    # and put back at the query (the nodes never reach mu = 1)
    odd = jnp.asarray(np.arange(s.n_modes) % 2, dtype)
    sn = jnp.asarray(np.sqrt(1.0 - nodes**2), dtype)
    scale = 1.0 + odd[:, None, None] * (sn[None, :, None] * sn[None, None, :] - 1.0)
    ms = jnp.einsum("qo,kmoi,qi->qkm", Lo, sol.ms / scale, Li)
    sq = safe_sqrt(1.0 - wo_in.z**2) * safe_sqrt(1.0 - wi_in.z**2)
    ms = ms * (1.0 + odd[None, None, :] * (sq[:, None, None] - 1.0))
    dphi = atan2(wo.y, wo.x) - atan2(wi.y, wi.x) - np.pi  # light travels along -wi
    m = np.arange(s.n_modes)
    cosm = jnp.cos(dphi[:, None] * m[None, :]) * np.where(m == 0, 1.0, 2.0)
    f = jnp.einsum("qkm,qm->qk", ms, cosm)
    base = (base_kind, base_value)
    if averaged:  # over rotations of the sample: a leading rotation axis
        g = jnp.asarray(_rotations(s.n_rot_single), dtype)[:, None]

        def rot(w):
            return ordinates_tilt.rotate_z(Vec3(w.x, w.y, jnp.broadcast_to(w.z, g.shape[:1] + w.z.shape)), g)

        ss = jnp.mean(_single_query(media, thickness, base, rot(wi_in), rot(wo_in), dtype), axis=0)
    else:
        ss = _single_query(media, thickness, base, wi_in, wo_in, dtype)
    if sol.tilt is not None:
        f = f + ordinates_tilt.evaluate(sol.tilt, np.asarray(gauss_legendre(s.tilt_mu, 0.0, 1.0)[0]),
                                        wi_in.z, atan2(-wi.y, -wi.x), wo_in.z, atan2(wo.y, wo.x), _lagrange,
                                        averaged, s.tilt_phi)
    f = (f + ss) * with_bands(factor)
    return jnp.where(with_bands(ok), f, 0.0)


def _refract_in(w: Vec3, eta):
    """The direction inside the host that leaves along ``w`` (pointing away), and F(mu)."""
    # mu_in^2 = 1 - (1 - mu^2)/eta^2 written without the cancellation of 1 - sin^2 (at eta = 1 it is mu
    # exactly; a grazing direction must not round to mu_in = 0 in float32)
    mu_in = safe_sqrt(eta * eta - 1.0 + w.z * w.z) / eta
    F, _, _, _ = fresnel_dielectric(w.z, eta)
    return Vec3(w.x / eta, w.y / eta, mu_in), F


# ------------------------------------------------------------------------------------
# public


def _prepare(media, thickness, base, eta, settings):
    settings = Settings() if settings is None else settings
    if not isinstance(settings, Settings):
        raise TypeError(f"ordinates: settings = {settings!r} must be an ordinates.Settings")
    settings.check()
    thickness = jnp.atleast_1d(jnp.asarray(thickness, jnp.result_type(float)))
    if base is None:
        base = ("lambert", jnp.zeros((1,), thickness.dtype))
    elif isinstance(base, tuple) and len(base) == 2 and hasattr(base[0], "eval"):
        base = ("model", base)
    else:
        base = ("lambert", jnp.atleast_1d(jnp.asarray(base, thickness.dtype)))
    if eta is not None and not isinstance(eta, jax.core.Tracer):
        e = float(np.asarray(eta))
        if not (math.isfinite(e) and e >= 1.0):
            raise ValueError(f"ordinates: eta = {eta!r} must be a finite host index >= 1 (None or 1: index-matched)")
        eta = None if e == 1.0 else jnp.asarray(e, thickness.dtype)
    return media, thickness, base, eta, settings


def solve(media, thickness, *, base=None, eta=None, settings: Settings | None = None) -> Solution:
    """Solve once for a parameter set: the multiply scattered Fourier kernels on the nodes.

    ``media``: :class:`.medium.Params` with a leading layer axis (band fields (L, B));
    ``thickness``: (L,) in base mean free paths, top layer first; ``base``: ``None`` (black),
    a Lambertian albedo (scalar or per band), or ``(model, params)`` of a library BSDF with a
    deterministic eval (assumed isotropic about the normal); ``eta``: host index of the
    stack under a smooth top interface (``None``: index-matched).
    """
    media, thickness, base, eta, s = _prepare(media, thickness, base, eta, settings)
    return _solution(media, thickness, base[1], eta, s, base[0])


def brdf(media, thickness, wi: Vec3, wo: Vec3, *, base=None, eta=None, azimuth: str = "averaged",
         settings: Settings | None = None, solution: Solution | None = None):
    """BRDF f(wi, wo) [1/sr] of the stack, bands last (see the module docstring).

    ``wi``, ``wo``: Vec3 pointing away from the surface (z = normal), broadcast against each
    other; ``azimuth``: "averaged" (over rotations of the sample about the normal) or "fixed"
    (the platelets tilted about x); ``solution``: a :func:`solve` result to reuse.
    """
    if azimuth not in ("averaged", "fixed"):
        raise ValueError(f"ordinates: azimuth = {azimuth!r} must be 'averaged' or 'fixed'")
    media, thickness, base, eta, s = _prepare(media, thickness, base, eta, settings)
    return _evaluate(media, thickness, base, eta, wi, wo, azimuth, s, solution)


def _evaluate(media, thickness, base, eta, wi, wo, azimuth, s, solution=None):
    """Solve (unless given a solution) and evaluate at broadcast directions; ``base`` = (kind, value)."""
    if solution is None:
        solution = _solution(media, thickness, base[1], eta, s, base[0])
    shape = jnp.broadcast_shapes(jnp.shape(wi.x), jnp.shape(wo.x))
    flat = lambda w: Vec3(*(jnp.broadcast_to(jnp.asarray(v, thickness.dtype), shape).ravel() for v in w))  # noqa: E731
    f = _brdf(media, thickness, base[1], eta, flat(wi), flat(wo), solution, s, base[0], azimuth == "averaged")
    return f.reshape(shape + f.shape[-1:])


def fourier_kernels(media, thickness, mu, *, base=None, eta=None, settings: Settings | None = None):
    """Fourier modes (B, M, k, k) of the reflection inside the host at the cosines ``mu``
    (placed on the node list with zero weight: no interpolation), propagation convention,
    index order [out, in]; f_inside = sum_m (2 - delta_m0) K_m cos(m dphi_propagation)."""
    media, thickness, base, eta, s = _prepare(media, thickness, base, eta, settings)
    return _kernels_at(media, thickness, base[1], eta, jnp.asarray(mu, thickness.dtype), s, base[0])


@partial(jax.jit, static_argnames=("s", "base_kind"))
def _kernels_at(media, thickness, base_value, eta, mu, s, base_kind):
    R, _ = _solve(media, thickness, (base_kind, base_value), eta, mu, s)
    n = s.n_nodes
    return R[:, :, n:, n:]


def brdf_traced(media, thickness, wi: Vec3, wo: Vec3, *, base, eta, azimuth: str, settings: Settings):
    """:func:`brdf` without validation, for use inside a model's kernel (parameters may be
    traced): ``base`` a Lambertian albedo array (bands) or ``(model, params)``, ``eta`` an array
    (1: index-matched; the interface then reflects nothing) or None."""
    base = ("model", base) if isinstance(base, tuple) else ("lambert", base)
    return _evaluate(media, thickness, base, eta, wi, wo, azimuth, settings)
