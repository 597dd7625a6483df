"""The tilt correction of :mod:`.ordinates`: the multiply scattered light of the *oriented*
medium minus that of its azimuth mixture, from a coarse full-azimuth discrete-ordinates solve.

:mod:`.ordinates` computes the multiply scattered light of the azimuth mixture of a tilted
platelet population (modes decouple; cheap and fine). The oriented medium differs at second
order in the platelets' anisotropy: a few percent at theta_p = 52 deg (Padrón Table A.1, Matte 2).
The difference is smooth, so a coarse solve resolves it: directions on a full (mu, phi) grid
(``n_mu`` Gauss cosines x ``n_phi`` uniform azimuths per hemisphere, dense operators of
n_mu n_phi directions), the same starting layer, doubling and adding (:mod:`.kernel_ops`, the
up-down asymmetric adding equations: an oriented tilted slab seen from below is its image
rotated by pi, which also lets its doubling get by with one solve per step), once with the
oriented kernels and once with the mixture's on the same grid, so that the discretisation errors
of the two cancel in the difference. The mixture's kernels are the oriented ones averaged over
the grid's rotations (permutations of the grid), and being rotation invariant it is solved per
azimuthal mode. Single scattering is left out of both (:mod:`.ordinates` evaluates it exactly).

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
from .kernel_ops import Op, add, cmul, doubled_slab, left, phi, resolvent, right

ALPHA_MIN = 0.25  # resolvable platelet roughness of the coarse grid (cf. ordinates.resolvable_alpha)


def _grid(n_mu, n_phi, dtype):
    x, w = gauss_legendre(n_mu, 0.0, 1.0)
    ph = 2.0 * np.pi * np.arange(n_phi) / n_phi
    mu = np.repeat(x, n_phi)
    az = np.tile(ph, n_mu)
    c = np.repeat(2.0 * np.pi * x * w / n_phi, n_phi)
    return jnp.asarray(mu, dtype), jnp.asarray(az, dtype), jnp.asarray(c, dtype), x


def direction(mu, az, up) -> Vec3:
    """Unit vector at polar cosine ``mu`` (> 0) and azimuth ``az``, travelling up (``up`` True
    or +1) or down (False or -1; an array of signs broadcasts)."""
    s = jnp.sqrt(jnp.maximum(1.0 - mu * mu, 0.0))
    sign = (1.0 if up else -1.0) if isinstance(up, bool) else up
    return Vec3(s * jnp.cos(az), s * jnp.sin(az), sign * mu)


def rotate_z(w: Vec3, g) -> Vec3:
    """w rotated by the angle g (radians, broadcasts) about the normal z."""
    c, s = jnp.cos(g), jnp.sin(g)
    return Vec3(c * w.x - s * w.y, s * w.x + c * w.y, w.z)


def _raw_kernels(m, mu, az):
    """sigma_s f of the oriented medium between the grid's directions for the four in/out
    combinations (dict of (B, N, N) [out, in]), the extinction (N,) and sigma_s (B, N) per
    direction (even: up = down)."""
    names = ("R", "T", "Rs", "Ts")
    # one evaluation over a leading axis of the four combinations (compiled once, not four times)
    in_up = np.array([-1.0, -1.0, 1.0, 1.0])[:, None, None]
    out_up = np.array([1.0, -1.0, -1.0, 1.0])[:, None, None]
    d_in = direction(mu[None, None, :], az[None, None, :], in_up)
    wi = Vec3(-d_in.x, -d_in.y, -d_in.z)
    wo = direction(mu[None, :, None], az[None, :, None], out_up)
    S = jnp.moveaxis(med.scattering_coefficient(m, wi, wo), -1, 1)  # (4, B, N, N)
    out = {name: S[j] for j, name in enumerate(names)}
    w = direction(mu, az, True)
    ext = med.extinction(m, w)
    sig_s = jnp.moveaxis(med.albedo(m, w) * ext[..., None], -1, 0)
    return out, ext, sig_s


def rotation_average(X, n_mu, n_phi):
    """A grid kernel (B, N, N) [out, in] averaged over the rotations of the sample by the grid's
    azimuth steps (a rotation permutes the grid): kappa (B, n_mu, n_mu, n_phi) [mu_out, mu_in,
    k], the kernel of the azimuth mixture at the azimuth difference phi_out - phi_in = k steps."""
    X4 = jnp.moveaxis(X.reshape(X.shape[0], n_mu, n_phi, n_mu, n_phi), 3, 2)  # [b, mu_o, mu_i, phi_o, phi_i]
    k, l = np.meshgrid(np.arange(n_phi), np.arange(n_phi), indexing="ij")
    return jnp.mean(X4[..., (l + k) % n_phi, l], axis=-1)


def _expand(kappa, n_phi):
    """The grid kernel (B, N, N) of a rotation-invariant kappa (B, n_mu, n_mu, n_phi)."""
    k = (np.arange(n_phi)[:, None] - np.arange(n_phi)[None, :]) % n_phi  # [phi_o, phi_i]
    X = jnp.moveaxis(kappa[..., k], 2, 3)  # [b, mu_o, phi_o, mu_i, phi_i]
    B, n_mu = kappa.shape[0], kappa.shape[1]
    return X.reshape(B, n_mu * n_phi, n_mu * n_phi)


def _cosines(n_phi, dtype):
    """cos(2 pi m k / n_phi), m = 0..n_phi/2 (rows), k = 0..n_phi-1: the real DFT of an even
    sequence (the mixture is mirror symmetric: kappa(k) = kappa(-k))."""
    m = np.arange(n_phi // 2 + 1)
    return jnp.asarray(np.cos(2.0 * np.pi * m[:, None] * np.arange(n_phi)[None, :] / n_phi), dtype)


def _to_modes(kappa):
    """kappa (B, n_mu, n_mu, n_phi) -> azimuthal modes (B, M, n_mu, n_mu): composition of
    rotation-invariant grid kernels (sum over the grid with weights c) is a product per mode."""
    return jnp.einsum("mk,boik->bmoi", _cosines(kappa.shape[-1], kappa.dtype), kappa)


def _from_modes(K, n_phi):
    """The inverse of :func:`_to_modes`: modes (B, M, n_mu, n_mu) -> kappa (B, n_mu, n_mu, n_phi)."""
    w = np.full(n_phi // 2 + 1, 2.0)
    w[0] = w[-1] = 1.0  # m = 0 and m = n_phi/2 appear once in the full DFT, the others twice
    cos = _cosines(n_phi, K.dtype) * jnp.asarray(w / n_phi, K.dtype)[:, None]
    return jnp.einsum("mk,bmoi->boik", cos, K)


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

    def sweep(_, b):
        total = jnp.einsum("o,bo,boi->bi", dwf, b[:, rev], full) * b
        return b * jnp.sqrt(target / jnp.where(total > 0, total, target))

    b = jax.lax.fori_loop(0, n_iter, sweep, jnp.ones_like(target))  # a loop, not unrolled: compile time
    full = b[:, rev][:, :, None] * full * b[:, None, :]
    return {"Ts": full[:, :N, :N], "R": full[:, :N, N:], "Rs": full[:, N:, :N], "T": full[:, N:, N:]}


def _slab(K, sig_up, t, mu, c, n, n_doublings, opp):
    """Op of one oriented slab. Seen from below it is its own image rotated by pi about the
    normal (the platelets' D is centrally symmetric): Rs = P R P, Ts = P T P and the direct
    beam travelling up at (mu, phi) is the one travelling down at (mu, phi + pi), P the
    permutation ``opp``. The doubling carries R and T only: one solve per step, the adding
    equations' V = P W P."""
    a_up = sig_up / mu
    a_dn = a_up[opp]
    t0 = t * 2.0 ** (-n_doublings)
    inv = t0 / (mu[:, None] * mu[None, :])
    R0 = K["R"] * inv * phi(t0 * (a_up[:, None] + a_dn[None, :]))
    T0 = K["T"] * jnp.exp(-t0 * a_dn)[:, None] * inv * phi(t0 * (a_dn[None, :] - a_dn[:, None]))
    mirror = lambda X: X[..., opp, :][..., :, opp]  # noqa: E731

    def step(RT, level):
        R, T = RT
        e = jnp.exp(-(t0 * 2.0**level) * a_dn)
        Ts, es = mirror(T), e[opp]
        W = resolvent(R, mirror(R), c, n)  # (I - R C Rs C)^-1 R
        R2 = R + left(es, Ts, right(W, e, T, c, n), c, n)
        T2 = (e[:, None] * T + T * e[None, :] + cmul(T, T, c, n)
              + left(e, T, right(cmul(mirror(W), R, c, n), e, T, c, n), c, n))
        return (R2, T2), None

    (R, T), _ = jax.lax.scan(step, (R0, T0), jnp.arange(n_doublings, dtype=mu.dtype))
    return Op(R, T, mirror(R), mirror(T), jnp.exp(-t * a_dn), jnp.exp(-t * a_up))


def _oriented(K, ext, t, mu, c, n, n_doublings, opp):
    """The oriented slab's Op and its single-scattering reflection (from above, over nothing)."""
    op = _slab(K, ext, t, mu, c, n, n_doublings, opp)
    x = (ext / mu)[:, None] + (ext[opp] / mu)[None, :]
    return op, K["R"] * (-jnp.expm1(-t * x) / (x * mu[:, None] * mu[None, :]))


def _mixture(K, ext, t, mu_x, c_x, n_doublings, n_phi):
    """The azimuth mixture's slab in modes (:func:`_to_modes`; up-down symmetric: R = Rs) and
    its single-scattering reflection; ``K`` the mixture's rotation-averaged kernels (kappa)."""
    SR, ST = _to_modes(K["R"]), _to_modes(K["T"])
    op = doubled_slab(SR, ST, ext, t, mu_x, c_x, mu_x.shape[0], n_doublings)
    a = ext / mu_x
    x = a[:, None] + a[None, :]
    return op, SR * (-jnp.expm1(-t * x) / (x * mu_x[:, None] * mu_x[None, :]))


def _ms(layers, Rb, W, e_of, c, n):
    """Multiply scattered reflection of a stack over a base (kernel ``Rb``) under an optional
    interface (weights ``W`` per direction, or None): ``layers`` a list of (Op, single
    scattering); ``e_of(op)`` the direct beams (up, down) of an Op."""
    stack, ss = None, 0.0
    up = dn = jnp.ones_like(c)
    for op, single in layers:
        ss = ss + (up[:, None] * dn[None, :]) * single
        e_up, e_dn = e_of(op)
        up, dn = up * e_up, dn * e_dn
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
    grid's directions; ``W_mu``: the interface's weights per Gauss cosine (or None).

    The mixture is the oriented medium averaged over rotations by the grid's azimuth steps: a
    rotation permutes the grid, so its kernels are the oriented ones permuted and averaged
    (:func:`rotation_average`; the discretisation errors of the two cancel in the difference),
    and being rotation invariant it is solved per azimuthal mode (n_phi/2 + 1 blocks of
    n_mu x n_mu instead of one dense operator of n_mu n_phi directions)."""
    mu, az, c, x = _grid(n_mu, n_phi, dtype)
    n = mu.shape[0]
    opp = _opposite(n_mu, n_phi)
    mu_x = jnp.asarray(x, dtype)
    c_x = c.reshape(n_mu, n_phi)[:, 0]
    W = None if W_mu is None else jnp.repeat(W_mu, n_phi) / n_phi
    oriented, mixture = [], []
    for k in range(thickness.shape[0]):
        m = med.Params(**{f: getattr(media, f)[k] for f in med.FIELDS})
        m = m.replace(alpha=jnp.sqrt(jnp.sqrt(m.alpha**4 + ALPHA_MIN**4)))
        K, ext, sig_s = _raw_kernels(m, mu, az)
        ext_x = jnp.mean(ext.reshape(n_mu, n_phi), axis=1)
        sig_s_x = jnp.broadcast_to(jnp.mean(sig_s.reshape(-1, n_mu, n_phi), axis=2)[..., None],
                                   sig_s.shape[:1] + (n_mu, n_phi)).reshape(sig_s.shape)
        Km = {b: _expand(rotation_average(X, n_mu, n_phi), n_phi) for b, X in K.items()}
        # both balanced in one loop (stacked along the bands axis): one compiled loop, not two
        B = sig_s.shape[0]
        both = _balance({b: jnp.concatenate([K[b], Km[b]]) for b in K}, jnp.concatenate([sig_s, sig_s_x]),
                        c / mu, n_mu, n_phi)
        Ko, Km = ({b: X[:B] for b, X in both.items()}, {b: X[B:] for b, X in both.items()})
        Km = {b: rotation_average(Km[b], n_mu, n_phi) for b in ("R", "T")}  # up-down symmetric: Rs = R, Ts = T
        oriented.append(_oriented(Ko, ext, thickness[k], mu, c, n, n_doublings, opp))
        mixture.append(_mixture(Km, ext_x, thickness[k], mu_x, c_x, n_doublings, n_phi))
    Rb = base_grid(mu, az)
    Rb_x = _to_modes(rotation_average(Rb, n_mu, n_phi))
    W_x = None if W_mu is None else W_mu / n_phi
    R_or = _ms(oriented, Rb, W, lambda op: (op.e_up, op.e), c, n)
    R_mix = _ms(mixture, Rb_x, W_x, lambda op: (op.e, op.e), c_x, n_mu)
    return R_or - _expand(_from_modes(R_mix, n_phi), n_phi), x


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
        Wd = _trig_weights(phi_o - phi_i, n_phi)
        return jnp.einsum("qa,back,qk,qc->qb", Lo, rotation_average(C, n_mu, n_phi), Wd, Li)
    Wo, Wi = _trig_weights(phi_o, n_phi), _trig_weights(phi_i, n_phi)
    return jnp.einsum("qa,qk,bakcl,qc,ql->qb", Lo, Wo, C4, Li, Wi)

