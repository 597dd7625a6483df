"""The snake skin's film and its Nyström solve (Padrón 2025, Ch. 3; spec M26, M38).

The building blocks of :mod:`.model` and :mod:`.mc`: the film's Airy reflectance seen from
above and from below (:func:`_film_R`, :func:`_film_Rs`), the absorbing diffuse BRDF f_1
(Padrón Eq. 3.6, :func:`_f1`), and the Nyström solution of the composition equation
F(mu_i, mu_o) = f_1(mu_i, mu_o) + 2 pi int_0^1 f_1(mu_i, mu') mu' R_u(mu') F(mu', mu_o) dmu'
(:func:`_solve`). ``p`` is always a :class:`appearance_jax.bsdf.snake.Params`.

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
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ...core import spectral
from ...core.linalg import solve_diagonally_dominant
from ...core.model import as_bands
from ...core.quadrature import gauss_legendre
from ...optics.thinfilm import airy


def _wavelengths(p):
    return spectral.band_wavelengths(p.color, p.wavelengths)


def _out(p, x):
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


def _film_R(p, mu, wl, extra: int, side: str):
    """Unpolarised film reflectance at cosine ``mu`` (aligned with ``wl``).

    ``extra``: number of trailing axes of mu/wl beyond the parameters' own shape.
    ``side="top"``: light from the eta0 side; ``"under"``: the underside per ``p.underside``.
    """
    d, e0, e1, e2 = (_scal(getattr(p, n), extra) for n in _FILM)
    if side == "under" and p.underside == "airy":
        e0, e2 = e2, e0
    # rounding puts R up to ~1e-15 above 1 under total internal reflection: keep T = 1 - R >= 0
    return jnp.clip(airy(mu, wl, d, e0, e1, e2).R, 0.0, 1.0)


def _film_Rs(p, wl, requests):
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


def _split(p):
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


def _nodes(p):
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


def _solve(p, directions=()):
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


def _u(p, kd, tau, mu_nodes, mu, n_bands: int):
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
