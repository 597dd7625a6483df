"""The tilt correction of :mod:`.ordinates`: the multiply scattered light of the *oriented*
medium minus that of its azimuth mixture, from a coarse full-azimuth discrete-ordinates solve.

:mod:`.ordinates` computes the multiply scattered light of the azimuth mixture of a tilted
platelet population (modes decouple; cheap and fine). The oriented medium differs at second
order in the platelets' anisotropy: a few percent at theta_p = 52 deg (Padrón Table A.1, Matte 2).
The difference is smooth, so a coarse solve resolves it: directions on a full (mu, phi) grid
(``n_mu`` Gauss cosines x ``n_phi`` uniform azimuths per hemisphere, dense operators of
n_mu n_phi directions), the same starting layer, doubling and adding (:mod:`.kernel_ops`, the
general, up-down asymmetric adding equations: an oriented tilted slab seen from below is its
mirror image), once with the oriented kernels and once with the mixture's on the same grid, so
that the discretisation errors of the two cancel in the difference. Single scattering is left
out of both (:mod:`.ordinates` evaluates it exactly).

The correction is returned on the coarse grid and evaluated at query directions by Lagrange
interpolation in mu and trigonometric interpolation in the azimuths (``azimuth="fixed"``), or
first averaged over rotations of the sample (exact on the uniform azimuth grid: a rotation by
a grid step is a permutation) and summed over its Fourier modes (``"averaged"``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..core.quadrature import gauss_legendre
from ..core.vec import Vec3
from . import medium as med
from .kernel_ops import Op, add, left, phi, resolvent, right

ALPHA_MIN = 0.25  # resolvable platelet roughness of the coarse grid (cf. ordinates.resolvable_alpha)


def _grid(n_mu, n_phi, dtype):
    x, w = gauss_legendre(n_mu, 0.0, 1.0)
    ph = 2.0 * np.pi * np.arange(n_phi) / n_phi
    mu = np.repeat(x, n_phi)
    az = np.tile(ph, n_mu)
    c = np.repeat(2.0 * np.pi * x * w / n_phi, n_phi)
    return jnp.asarray(mu, dtype), jnp.asarray(az, dtype), jnp.asarray(c, dtype), x


def direction(mu, az, up: bool) -> Vec3:
    """Unit vector at polar cosine ``mu`` (> 0) and azimuth ``az``, travelling up or down."""
    s = jnp.sqrt(jnp.maximum(1.0 - mu * mu, 0.0))
    return Vec3(s * jnp.cos(az), s * jnp.sin(az), mu if up else -mu)


def rotate_z(w: Vec3, g) -> Vec3:
    """w rotated by the angle g (radians, broadcasts) about the normal z."""
    c, s = jnp.cos(g), jnp.sin(g)
    return Vec3(c * w.x - s * w.y, s * w.x + c * w.y, w.z)


def _kernels(m, mu, az, c, rotations, n_phi):
    """sigma_s f on the grid for the four in/out combinations and sigma(w) per direction,
    averaged over the given rotations of the platelets (one rotation 0: the oriented medium),
    each column scaled to the exact sigma_s of its incident direction (below).
    Returns a dict of (B, N, N) [out, in] and the (N,) extinction (even: up = down)."""
    g = jnp.asarray(np.asarray(rotations, float), mu.dtype)[:, None, None]  # a leading rotation axis
    out = {}
    for name, in_up, out_up in (("R", False, True), ("T", False, False), ("Rs", True, False), ("Ts", True, True)):
        d_in = direction(mu[None, :], az[None, :], in_up)
        wi = Vec3(-d_in.x, -d_in.y, -d_in.z)
        wo = direction(mu[:, None], az[:, None], out_up)
        S = jnp.mean(med.scattering_coefficient(m, rotate_z(wi, g), rotate_z(wo, g)), axis=0)
        out[name] = jnp.moveaxis(S, -1, 0)
    w = rotate_z(direction(mu, az, True), g[:, :, 0])
    ext = med.extinction(m, w)
    sig = jnp.mean(ext, axis=0)
    sig_s = jnp.moveaxis(jnp.mean(med.albedo(m, w) * ext[..., None], axis=0), -1, 0)  # (B, N), even in w
    out = _balance(out, sig_s, c / mu, mu.shape[0] // n_phi, n_phi)
    return out, sig


def _balance(K, sig_s, dw, n_mu, n_phi, n_iter: int = 8):
    """Scale the point-sampled kernels so that every incident direction scatters exactly its
    sigma_s (energy), keeping reciprocity K(d', d) = K(-d, -d').

    On a coarse grid a platelet lobe's energy is off by percents, differently for each
    incident direction of the oriented medium (the mixture averages them), and the correction
    would be the difference of two quadrature errors (Matte 2: 10 standard errors of the walk
    off). The scaling K'(d', d) = b(-d') K(d', d) b(d) (symmetric Sinkhorn iterations over the
    whole sphere of propagation directions, up first) keeps the reciprocal pairs equal."""
    N = n_mu * n_phi
    opposite = _opposite(n_mu, n_phi)
    full = jnp.concatenate([jnp.concatenate([K["Ts"], K["R"]], axis=-1),
                            jnp.concatenate([K["Rs"], K["T"]], axis=-1)], axis=-2)  # (B, 2N, 2N) [out, in]
    rev = np.concatenate([N + opposite, opposite])  # -d: up <-> down at the opposite azimuth
    target = jnp.concatenate([sig_s, sig_s[:, opposite]], axis=-1)  # sigma_s(-d) = sigma_s(d)
    dwf = jnp.concatenate([dw, dw])
    b = jnp.ones_like(target)
    for _ in range(n_iter):
        total = jnp.einsum("o,bo,boi->bi", dwf, b[:, rev], full) * b
        b = b * jnp.sqrt(target / jnp.where(total > 0, total, target))
    full = b[:, rev][:, :, None] * full * b[:, None, :]
    return {"Ts": full[:, :N, :N], "R": full[:, :N, N:], "Rs": full[:, N:, :N], "T": full[:, N:, N:]}


def _slab(K, sig_up, sig_dn, t, mu, c, n, n_doublings):
    """Op of one oriented slab (up-down asymmetric: the direct beam and the single-scattering
    start use the extinction of each direction of travel)."""
    a_up, a_dn = sig_up / mu, sig_dn / mu
    t0 = t * 2.0 ** (-n_doublings)
    inv = t0 / (mu[:, None] * mu[None, :])

    def r(ao, ai):  # reflection start: in along ai, out along ao
        return inv * phi(t0 * (ao[:, None] + ai[None, :]))

    def tr(ao, ai):
        return jnp.exp(-t0 * ao)[:, None] * inv * phi(t0 * (ai[None, :] - ao[:, None]))

    op = Op(K["R"] * r(a_up, a_dn), K["T"] * tr(a_dn, a_dn), K["Rs"] * r(a_dn, a_up), K["Ts"] * tr(a_up, a_up),
            jnp.exp(-t0 * a_dn), jnp.exp(-t0 * a_up))

    def step(op, level):
        op = op._replace(e=jnp.exp(-(t0 * 2.0**level) * a_dn), es=jnp.exp(-(t0 * 2.0**level) * a_up))
        return add(op, op, c, n), None

    op, _ = jax.lax.scan(step, op, jnp.arange(n_doublings, dtype=mu.dtype))
    return op._replace(e=jnp.exp(-t * a_dn), es=jnp.exp(-t * a_up))


def _ms(media, thickness, Rb, W, mu, az, c, n, n_doublings, rotations, n_phi):
    """Multiply scattered reflection (B, N, N) of the stack over the base (kernel ``Rb``
    (B, N, N)) under an optional interface (weights ``W`` per direction, or None) on the grid."""
    stack, ss, up, dn = None, 0.0, jnp.ones_like(mu), jnp.ones_like(mu)
    opposite = _opposite(mu.shape[0] // n_phi, n_phi)
    for k in range(thickness.shape[0]):
        m = med.Params(**{f: getattr(media, f)[k] for f in med.FIELDS})
        m = m.replace(alpha=jnp.sqrt(jnp.sqrt(m.alpha**4 + ALPHA_MIN**4)))
        K, sig = _kernels(m, mu, az, c, rotations, n_phi)
        sig_dn = sig[opposite]  # sigma is even: down at (mu, phi) = up at (mu, phi + pi)
        op = _slab(K, sig, sig_dn, thickness[k], mu, c, n, n_doublings)
        x = (sig / mu)[:, None] + (sig_dn / mu)[None, :]
        single = -jnp.expm1(-thickness[k] * x) / (x * mu[:, None] * mu[None, :])
        ss = ss + (up[:, None] * dn[None, :]) * K["R"] * single
        up, dn = up * op.e_up, dn * op.e
        stack = op if stack is None else add(stack, op, c, n)
    ss = ss + up[:, None] * dn[None, :] * Rb
    Wb = resolvent(Rb, stack.Rs, c, n)
    R = stack.R + left(stack.e_up, stack.Ts, right(Wb, stack.e, stack.T, c, n), c, n)
    if W is not None:
        R = resolvent(R, jnp.diag(W / (c * c)), c, n)
    return R - ss


def _opposite(n_mu, n_phi):
    """Index of the grid direction at the same cosine and the opposite azimuth (phi + pi)."""
    j, k = np.divmod(np.arange(n_mu * n_phi), n_phi)
    return j * n_phi + (k + n_phi // 2) % n_phi


def correction(media, thickness, base_grid, W_mu, dtype, n_mu, n_phi, n_doublings=16):
    """Oriented minus mixture multiply scattered reflection (B, N, N) on the coarse grid and
    the grid's Gauss cosines. ``base_grid(mu, az)``: the base's kernel (B, N, N) between the
    grid's directions; ``W_mu``: the interface's weights per Gauss cosine (or None)."""
    mu, az, c, x = _grid(n_mu, n_phi, dtype)
    n = mu.shape[0]
    W = None if W_mu is None else jnp.repeat(W_mu, n_phi) / n_phi
    # the mixture's rotations are the grid's own azimuth steps: a rotation permutes the grid, so the
    # mixture's grid kernel is exactly the average of the oriented one and their discretisation
    # errors cancel in the difference
    rots = np.arange(n_phi) * (2.0 * np.pi / n_phi)
    Rb = base_grid(mu, az)
    oriented = _ms(media, thickness, Rb, W, mu, az, c, n, n_doublings, (0.0,), n_phi)
    mixture = _ms(media, thickness, Rb, W, mu, az, c, n, n_doublings, tuple(rots), n_phi)
    return oriented - mixture, x


def _trig_weights(phi_q, n_phi):
    """Weights (Q, n_phi) of the trigonometric interpolant through n_phi uniform samples."""
    k = np.arange(n_phi)
    d = phi_q[:, None] - 2.0 * np.pi * k[None, :] / n_phi
    m = np.arange(1, n_phi // 2)
    w = 1.0 + 2.0 * jnp.sum(jnp.cos(m[None, None, :] * d[..., None]), axis=-1) + jnp.cos((n_phi // 2) * d)
    return w / n_phi


def evaluate(C, x, mu_i, phi_i, mu_o, phi_o, lagrange, averaged: bool, n_phi: int):
    """The correction at queries (Q, B): incident propagation direction at cosine mu_i (down),
    azimuth phi_i; outgoing at mu_o (up), azimuth phi_o (propagation azimuths)."""
    B = C.shape[0]
    n_mu = x.shape[0]
    C4 = C.reshape(B, n_mu, n_phi, n_mu, n_phi)  # [b, mu_o, phi_o, mu_i, phi_i]
    Lo, Li = lagrange(mu_o, x), lagrange(mu_i, x)
    if averaged:
        # rotation average: C(mu_o, mu_i, dphi_k) = mean_l C[mu_o, l + k, mu_i, l]
        k = np.arange(n_phi)
        Cd = jnp.mean(jnp.stack([jnp.take(C4[..., l], (l + k) % n_phi, axis=2) for l in range(n_phi)]),
                      axis=0)  # (B, mu_o, k, mu_i)
        Wd = _trig_weights(phi_o - phi_i, n_phi)
        return jnp.einsum("qa,bakc,qk,qc->qb", Lo, Cd, Wd, Li)
    Wo, Wi = _trig_weights(phi_o, n_phi), _trig_weights(phi_i, n_phi)
    return jnp.einsum("qa,qk,bakcl,qc,ql->qb", Lo, Wo, C4, Li, Wi)

