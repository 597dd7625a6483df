"""Shared helpers of the Mitsuba 3 cross-checks (imported by the test_mitsuba_* files)."""

import numpy as np


def walter_beckmann_g1(w, au, av=None):
    """Walter et al. 2007, Eq. 27: the rational Beckmann G1 that Mitsuba 3 uses.

    ``w`` is an (N, 3) array of directions; the facet-side check is left to the caller.
    Written from the paper (rel. error < 0.35 % against the exact erf form).
    """
    av = au if av is None else av
    a = np.abs(w[:, 2]) / np.sqrt(np.maximum((au * w[:, 0]) ** 2 + (av * w[:, 1]) ** 2, 1e-300))
    return np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))


def max_rel_error(ours, ref, tiny):
    """(max relative error where |ref| > tiny * max|ref|, max abs error elsewhere / max|ref|, count)."""
    ours, ref = np.asarray(ours, float), np.asarray(ref, float)
    scale = np.max(np.abs(ref))
    big = np.abs(ref) > tiny * scale
    rel = np.max(np.abs(ours[big] - ref[big]) / np.abs(ref[big]))
    tiny_abs = np.max(np.abs(ours[~big] - ref[~big]), initial=0.0) / scale
    return rel, tiny_abs, int(big.sum())


def as_vec3(a):
    """(N, 3) rows -> float64 Vec3 (our side of a comparison runs in float64)."""
    from appearance_jax.core.vec import Vec3

    return Vec3.from_array(np.asarray(a, dtype=np.float64))
