"""Fresnel equations: dielectric (s/p amplitudes, reflectance, TIR), conductor, Schlick.

Conventions (M09 of the Padrón 2025 spec; Born & Wolf): light goes from medium i to
medium t; ``cos_i`` is the cosine of the incident angle with the interface normal on the
incident side; ``eta`` is the *relative* index eta_t / eta_i. Amplitudes are signed
(no separate pi phase jumps are needed anywhere downstream):

    r_s = (eta_i c_i - eta_t c_t) / (eta_i c_i + eta_t c_t)
    r_p = (eta_t c_i - eta_i c_t) / (eta_t c_i + eta_i c_t)
    t_s = 2 eta_i c_i / (eta_i c_i + eta_t c_t)
    t_p = 2 eta_i c_i / (eta_t c_i + eta_i c_t)

The unpolarised reflectance is F = (|r_s|^2 + |r_p|^2) / 2; F = 1 under total internal
reflection; the transmitted power is T = 1 - F.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..core.special import safe_sqrt


def snell_cos_t(cos_i, eta):
    """cos of the refraction angle (>= 0) and a validity flag (False under TIR).

    ``cos_i`` >= 0 and ``eta`` = eta_t / eta_i. Under TIR cos_t is returned as 0.
    """
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    valid = sin2_t <= 1.0
    return safe_sqrt(1.0 - sin2_t), valid


def fresnel_dielectric_amplitudes(cos_i, eta):
    """Signed real amplitudes ``(r_s, r_p, t_s, t_p)`` for 0 <= cos_i <= 1.

    Valid below the critical angle; under TIR the reflection amplitudes are returned with
    modulus 1 (the phase is dropped; use :func:`fresnel_amplitudes_complex` for it) and
    the transmission amplitudes are 0.
    """
    cos_t, valid = snell_cos_t(cos_i, eta)
    # eta_i = 1, eta_t = eta (amplitudes only depend on the ratio)
    ds = cos_i + eta * cos_t
    dp = eta * cos_i + cos_t
    ds = jnp.where(ds > 0, ds, 1.0)
    dp = jnp.where(dp > 0, dp, 1.0)
    r_s = jnp.where(valid, (cos_i - eta * cos_t) / ds, 1.0)
    r_p = jnp.where(valid, (eta * cos_i - cos_t) / dp, 1.0)
    t_s = jnp.where(valid, 2.0 * cos_i / ds, 0.0)
    t_p = jnp.where(valid, 2.0 * cos_i / dp, 0.0)
    return r_s, r_p, t_s, t_p


def normal_index(eta, eta0_sin0):
    """q = eta cos(theta) in a layer of (complex) index ``eta``, from Snell's invariant.

    ``eta0_sin0`` = eta_0 sin(theta_0) is conserved across parallel interfaces, so
    q = sqrt(eta^2 - (eta_0 sin theta_0)^2). The branch is the forward one (the wave
    travels or decays away from the incidence side): Im q > 0, or q >= 0 when q is real.
    A plain principal sqrt would pick -i|q| for a negative argument carrying a -0
    imaginary part (evanescent waves growing instead of decaying).

    q = 0 exactly (a layer hit exactly at its critical angle, or an index-matched layer at
    grazing incidence) is replaced by q = sqrt(machine epsilon): there the Airy formula is
    0/0 with a finite limit (r_01 -> 1, r_12 -> -1, phase -> 0), and the sqrt has an
    infinite derivative. The nudge keeps values continuous (error ~ sqrt(eps), 1e-8 in
    float64) and gradients finite instead of NaN.
    """
    eta = jnp.asarray(eta) + 0j
    arg = eta * eta - (jnp.asarray(eta0_sin0) + 0j) ** 2
    tiny = jnp.finfo(jnp.real(arg).dtype).eps
    q = jnp.sqrt(jnp.where(arg == 0, tiny + 0j, arg))
    flip = (q.imag < 0) | ((q.imag == 0) & (q.real < 0))
    return jnp.where(flip, -q, q)


def interface_amplitudes(q_i, q_t, eta_i, eta_t):
    """Complex ``(r_s, r_p, t_s, t_p)`` of one interface from q = eta cos(theta) on each side.

    Same convention as the cos form in the module docstring (multiply numerator and
    denominator of the p terms by eta_i eta_t):

        r_s = (q_i - q_t) / (q_i + q_t),              t_s = 2 q_i / (q_i + q_t)
        r_p = (eta_t^2 q_i - eta_i^2 q_t) / (eta_t^2 q_i + eta_i^2 q_t)
        t_p = 2 eta_i eta_t q_i / (eta_t^2 q_i + eta_i^2 q_t)

    It is the building block of the thin-film and multilayer solvers
    (:mod:`appearance_jax.optics.thinfilm`). A zero denominator (grazing incidence on an
    index-matched interface) gives r = 0, t = 1.
    """
    eta_i = jnp.asarray(eta_i) + 0j
    eta_t = jnp.asarray(eta_t) + 0j
    ei2, et2 = eta_i * eta_i, eta_t * eta_t
    ds = q_i + q_t
    dp = et2 * q_i + ei2 * q_t
    ok_s, ok_p = ds != 0, dp != 0
    ds = jnp.where(ok_s, ds, 1.0)
    dp = jnp.where(ok_p, dp, 1.0)
    r_s = jnp.where(ok_s, (q_i - q_t) / ds, 0j)
    r_p = jnp.where(ok_p, (et2 * q_i - ei2 * q_t) / dp, 0j)
    t_s = jnp.where(ok_s, 2.0 * q_i / ds, 1.0 + 0j)
    t_p = jnp.where(ok_p, 2.0 * eta_i * eta_t * q_i / dp, 1.0 + 0j)
    return r_s, r_p, t_s, t_p


def fresnel_amplitudes_complex(cos_i, eta_i, eta_t):
    """Complex amplitudes ``(r_s, r_p, t_s, t_p, cos_t)`` for complex indices.

    ``eta_i`` and ``eta_t`` may be complex (n + i k, absorbing media); ``eta_i`` should be
    real (or weakly absorbing) for ``cos_i`` to mean an angle. cos_t = q_t / eta_t with the
    forward branch of :func:`normal_index`, which also gives the evanescent solution
    (|r| = 1) under total internal reflection.
    """
    cos_i = jnp.asarray(cos_i).astype(jnp.result_type(cos_i, jnp.complex64))
    eta_i = jnp.asarray(eta_i) + 0j
    eta_t = jnp.asarray(eta_t) + 0j
    q_i = eta_i * cos_i
    q_t = normal_index(eta_t, eta_i * jnp.sqrt(1.0 - cos_i * cos_i))
    r_s, r_p, t_s, t_p = interface_amplitudes(q_i, q_t, eta_i, eta_t)
    return r_s, r_p, t_s, t_p, q_t / eta_t


def fresnel_dielectric(cos_i, eta):
    """Unpolarised dielectric reflectance for a signed ``cos_i`` (either side).

    ``eta`` = eta_inside / eta_outside, where "outside" is the side the normal points to.
    A negative ``cos_i`` means the light arrives from inside: the ratio is inverted.

    Returns ``(F, cos_t, eta_it, eta_ti)`` with ``cos_t`` the signed cosine of the
    transmitted direction (opposite sign to ``cos_i``; 0 under TIR), ``eta_it`` the
    relative index eta_t/eta_i seen by this direction and ``eta_ti = 1 / eta_it``.
    """
    outside = cos_i >= 0
    eta_it = jnp.where(outside, eta, 1.0 / eta)
    eta_ti = jnp.where(outside, 1.0 / eta, eta)
    ci = jnp.abs(cos_i)
    ct, valid = snell_cos_t(ci, eta_it)
    # F via s/p reflectances with eta_i = 1, eta_t = eta_it
    ds = ci + eta_it * ct
    dp = eta_it * ci + ct
    ds = jnp.where(ds > 0, ds, 1.0)
    dp = jnp.where(dp > 0, dp, 1.0)
    r_s = (ci - eta_it * ct) / ds
    r_p = (eta_it * ci - ct) / dp
    F = jnp.where(valid, 0.5 * (r_s * r_s + r_p * r_p), 1.0)
    cos_t = jnp.where(outside, -ct, ct)
    cos_t = jnp.where(valid, cos_t, 0.0)
    return F, cos_t, eta_it, eta_ti


def fresnel_dielectric_terms(cos_i, eta):
    """``(r, t, d)`` with F = r / d and 1 - F = t / d: the unpolarised reflectance and
    transmittance of a dielectric as fractions over one denominator, for a BSDF that folds
    them into its own single division (the hot loop of the rough dielectric and plastic).

    ``cos_i`` in [0, 1] (values above 1 are clamped); ``eta`` = eta_t / eta_i. With
    A, B = c -+ eta c_t and C, E = eta c -+ c_t (the numerators and denominators of r_s, r_p):

        r = A^2 E^2 + C^2 B^2,    t = 4 eta c c_t (B^2 + E^2),    d = 2 B^2 E^2

    (R_s + R_p) / 2 over the common denominator; t uses 1 - R_s = 4 eta c c_t / B^2 (and the
    same for p), so r + t = d and nothing cancels in 1 - F near grazing. Under total internal
    reflection c_t = 0 gives r = d, t = 0 (F = 1) without a select; d > 0 except at cos_i = 0
    under total internal reflection, which the caller masks. Same values as
    :func:`fresnel_dielectric` (to rounding, and its float32 accuracy where ``eta`` varies
    per element) with two divisions fewer. Float32 with one ``eta`` for all elements and
    eta < 1: near the critical angle XLA:CPU may divide by eta^2 as a multiplication by its
    rounded reciprocal, which costs some accuracy there (about 3x the error of
    :func:`fresnel_dielectric`, ~1e-5 instead of ~3e-6, a few ulp of the cosine from it).
    """
    c = jnp.minimum(cos_i, 1.0)
    ct = safe_sqrt(1.0 - (1.0 - c * c) / (eta * eta))
    a, b = c - eta * ct, c + eta * ct
    cp, e = eta * c - ct, eta * c + ct
    b2, e2 = b * b, e * e
    return a * a * e2 + cp * cp * b2, 4.0 * eta * c * ct * (b2 + e2), 2.0 * b2 * e2


def fresnel_conductor(cos_i, eta, k):
    """Unpolarised reflectance of a conductor with complex relative index eta + i k.

    ``cos_i`` in [0, 1] (values below 0 are treated as grazing). A real closed form of
    |r_s|^2 and |r_p|^2 (no complex autodiff); it equals the complex-amplitude result of
    :func:`fresnel_amplitudes_complex` (tested) and, with k = 0 and eta > 1,
    :func:`fresnel_dielectric`. Broadcasts ``eta`` and ``k`` against ``cos_i`` (e.g. a
    trailing RGB axis).
    """
    c = jnp.clip(cos_i, 0.0, 1.0)
    # Real formulation of |r_s|^2, |r_p|^2 (avoids complex autodiff): with
    # a^2 + b^2 = sqrt((eta^2 - k^2 - s^2)^2 + 4 eta^2 k^2) and a^2 = (that + eta^2 - k^2 - s^2) / 2,
    #   R_s = (t1 - t2) / (t1 + t2),  R_p = R_s (t3 - t4) / (t3 + t4),
    # so (R_s + R_p) / 2 = R_s t3 / (t3 + t4): one division per band instead of two (this
    # function is the hot loop of every conductor evaluation).
    c2 = c * c
    s2 = 1.0 - c2
    e2, k2 = eta * eta, k * k
    t0 = e2 - k2 - s2
    a2pb2 = safe_sqrt(t0 * t0 + 4.0 * e2 * k2)
    a = safe_sqrt(0.5 * (a2pb2 + t0))
    t1 = a2pb2 + c2
    t2 = 2.0 * c * a
    t3 = c2 * a2pb2 + s2 * s2
    t4 = t2 * s2
    return (t1 - t2) * t3 / jnp.maximum((t1 + t2) * (t3 + t4), 1e-30)


def schlick(cos_i, f0):
    """Schlick's approximation F0 + (1 - F0)(1 - cos)^5 (Schlick 1994)."""
    m = jnp.clip(1.0 - cos_i, 0.0, 1.0)
    m2 = m * m
    return f0 + (1.0 - f0) * m2 * m2 * m


def schlick_f0(eta):
    """Normal-incidence reflectance ((eta - 1)/(eta + 1))^2 of a dielectric."""
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def critical_angle(eta):
    """Critical angle (radians) from the dense side, ``eta`` = eta_dense / eta_rare > 1."""
    return jnp.arcsin(1.0 / eta)
