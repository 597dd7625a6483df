"""Single-interface Fresnel amplitudes and reflectances against the `tmm` package (S. Byrnes).

A stack of two semi-infinite media [n_i, n_t] with d = [inf, inf] is one interface; tmm
returns the complex r and t per polarisation and the power coefficients R and T.
"""

import numpy as np
import pytest

tmm = pytest.importorskip("tmm")

from appearance_jax.optics.fresnel import (  # noqa: E402
    fresnel_amplitudes_complex,
    fresnel_conductor,
    fresnel_dielectric,
    fresnel_dielectric_amplitudes,
)

ANGLES_DEG = (0.0, 15.0, 30.0, 45.0, 56.3, 60.0, 75.0, 85.0, 89.0)
# (eta_i, eta_t): air -> glass/water/diamond, glass -> air (TIR above 41.8 deg),
# air -> gold/aluminium-like conductors, a lossy dielectric, water -> metal
PAIRS = [
    (1.0, 1.5),
    (1.0, 1.333),
    (1.0, 2.42),
    (1.5, 1.0),
    (1.0, 0.27 + 2.94j),
    (1.0, 1.2 + 7.0j),
    (1.0, 2.0 + 0.5j),
    (1.333, 0.5 + 2.0j),
]


def _tmm(pol, n_i, n_t, th_deg):
    return tmm.coh_tmm(pol, [n_i, n_t], [np.inf, np.inf], np.radians(th_deg), 550.0)


@pytest.mark.parametrize("n_i, n_t", PAIRS)
def test_complex_amplitudes_match_tmm(n_i, n_t):
    for th in ANGLES_DEG:
        r_s, r_p, t_s, t_p, _ = fresnel_amplitudes_complex(np.cos(np.radians(th)), n_i, n_t)
        s = _tmm("s", n_i, n_t, th)
        p = _tmm("p", n_i, n_t, th)
        np.testing.assert_allclose(complex(r_s), s["r"], atol=1e-10, err_msg=f"r_s {n_i}->{n_t} at {th}")
        np.testing.assert_allclose(complex(r_p), p["r"], atol=1e-10, err_msg=f"r_p {n_i}->{n_t} at {th}")
        np.testing.assert_allclose(complex(t_s), s["t"], atol=1e-10, err_msg=f"t_s {n_i}->{n_t} at {th}")
        np.testing.assert_allclose(complex(t_p), p["t"], atol=1e-10, err_msg=f"t_p {n_i}->{n_t} at {th}")


@pytest.mark.parametrize("n_i, n_t", [p for p in PAIRS if np.imag(p[1]) == 0])
def test_real_amplitudes_and_unpolarised_reflectance_match_tmm(n_i, n_t):
    eta = n_t / n_i
    for th in ANGLES_DEG:
        c = np.cos(np.radians(th))
        s = _tmm("s", n_i, n_t, th)
        p = _tmm("p", n_i, n_t, th)
        R = 0.5 * (s["R"] + p["R"])
        # signed real amplitudes (meaningful below the critical angle only)
        if np.sin(np.radians(th)) < eta:
            r_s, r_p, t_s, t_p = fresnel_dielectric_amplitudes(c, eta)
            np.testing.assert_allclose([r_s, r_p, t_s, t_p], np.real([s["r"], p["r"], s["t"], p["t"]]),
                                       atol=1e-10, err_msg=f"{n_i}->{n_t} at {th}")
            # transmitted power: tmm's T and ours, 1 - F
            np.testing.assert_allclose(1.0 - fresnel_dielectric(c, eta)[0], 0.5 * (s["T"] + p["T"]), atol=1e-10)
        # unpolarised reflectance from either side: normal pointing into medium i
        np.testing.assert_allclose(fresnel_dielectric(c, eta)[0], R, atol=1e-10, err_msg=f"{n_i}->{n_t} at {th}")
        # the same interface seen from the other side (cos < 0, eta = inside/outside)
        np.testing.assert_allclose(fresnel_dielectric(-c, n_i / n_t)[0], R, atol=1e-10)


@pytest.mark.parametrize("n_t", [p[1] for p in PAIRS if p[0] == 1.0])
def test_conductor_reflectance_matches_tmm(n_t):
    # our real formulation of the conductor reflectance (incident medium: air)
    th = np.array(ANGLES_DEG)
    R_ref = np.array([0.5 * (_tmm("s", 1.0, n_t, a)["R"] + _tmm("p", 1.0, n_t, a)["R"]) for a in th])
    F = fresnel_conductor(np.cos(np.radians(th)), np.real(n_t), np.imag(n_t))
    np.testing.assert_allclose(F, R_ref, atol=1e-10)
