"""Thin films and multilayer stacks against the `tmm` package (S. Byrnes, coh_tmm).

Single films (:func:`airy`) and stacks of up to 6 media (:func:`multilayer`), s and p, many
angles and wavelengths, absorbing films and conductor substrates, frustrated total internal
reflection: complex amplitudes r, t and powers R, T agree to 1e-10 in float64.
"""

import numpy as np
import pytest

tmm = pytest.importorskip("tmm")

from appearance_jax.optics import thinfilm as tf  # noqa: E402

ANGLES_DEG = np.array([0.0, 10.0, 30.0, 45.0, 60.0, 75.0, 85.0, 89.0])
WAVELENGTHS = np.array([380.0, 450.0, 530.0, 610.0, 700.0, 780.0])

FILMS = {  # (eta0, eta1, eta2), thickness nm
    "keratin_in_air": ((1.0, 1.56, 1.0), 900.0),
    "soap_film": ((1.0, 1.33, 1.0), 450.0),
    "ar_coating_on_glass": ((1.0, 1.38, 1.52), 99.6),
    "absorbing_film_on_gold": ((1.0, 1.9 + 0.3j, 0.27 + 2.94j), 60.0),
    "oxide_on_aluminium": ((1.0, 1.65, 1.2 + 7.0j), 180.0),
    "frustrated_tir_glass_air_glass": ((1.5, 1.0, 1.5), 300.0),
    "water_film_under_glass": ((1.5, 1.33, 1.0), 1200.0),
}

STACKS = {  # indices (incidence ... exit), inner thicknesses nm
    "four_layers": ((1.0, 2.0, 1.3 + 0.2j, 1.7, 0.5 + 3.0j), (90.0, 245.0, 400.0)),
    "bragg_pair_x2": ((1.0, 2.3, 1.38, 2.3, 1.38, 1.52), (60.0, 100.0, 60.0, 100.0)),
    "metal_in_dielectrics": ((1.33, 1.5, 0.06 + 4.1j, 1.45, 1.0), (150.0, 30.0, 500.0)),
    "tir_gap": ((1.7, 1.0, 1.7, 1.2), (150.0, 80.0)),
}


def _tmm_grid(indices, thicknesses):
    d = [np.inf, *thicknesses, np.inf]
    out = {}
    for pol in "sp":
        rr = np.empty((ANGLES_DEG.size, WAVELENGTHS.size), complex)
        tt, RR, TT = rr.copy(), np.empty(rr.shape), np.empty(rr.shape)
        for a, th in enumerate(ANGLES_DEG):
            for b, wl in enumerate(WAVELENGTHS):
                res = tmm.coh_tmm(pol, list(indices), d, np.radians(th), wl)
                rr[a, b], tt[a, b], RR[a, b], TT[a, b] = res["r"], res["t"], res["R"], res["T"]
        out[pol] = (rr, tt, RR, TT)
    return out


def _compare(ours, ref):
    for pol in "sp":
        r, t, R, T = (np.asarray(getattr(ours, f"{q}_{pol}")) for q in ("r", "t", "R", "T"))
        rr, tt, RR, TT = ref[pol]
        np.testing.assert_allclose(r, rr, atol=1e-10, err_msg=f"r_{pol}")
        np.testing.assert_allclose(t, tt, atol=1e-10, err_msg=f"t_{pol}")
        np.testing.assert_allclose(R, RR, atol=1e-10, err_msg=f"R_{pol}")
        np.testing.assert_allclose(T, TT, atol=1e-10, err_msg=f"T_{pol}")


@pytest.mark.parametrize("name", list(FILMS))
def test_single_film_matches_tmm(name):
    (e0, e1, e2), d = FILMS[name]
    c = np.cos(np.radians(ANGLES_DEG))[:, None]
    ours = tf.airy(c, WAVELENGTHS[None, :], d, e0, e1, e2)
    ref = _tmm_grid((e0, e1, e2), (d,))
    _compare(ours, ref)
    # the stack solver agrees on the same film
    _compare(tf.multilayer(c, WAVELENGTHS[None, :], np.array([e0, e1, e2]), np.array([d])), ref)


@pytest.mark.parametrize("name", list(STACKS))
def test_multilayer_matches_tmm(name):
    n, d = STACKS[name]
    c = np.cos(np.radians(ANGLES_DEG))[:, None]
    ours = tf.multilayer(c, WAVELENGTHS[None, :], np.array(n), np.array(d))
    _compare(ours, _tmm_grid(n, d))


def test_batched_stacks_broadcast_over_thickness():
    """A leading batch axis of thicknesses (one stack per row) gives each row's tmm result."""
    n = np.array([1.0, 1.45, 2.1, 1.52])
    d = np.array([[80.0, 120.0], [100.0, 60.0], [0.0, 300.0]])
    ours = tf.multilayer(np.cos(np.radians(30.0)), 550.0, n, d)
    for row in range(3):
        ref = tmm.coh_tmm("s", list(n), [np.inf, *d[row], np.inf], np.radians(30.0), 550.0)
        assert abs(complex(ours.r_s[row]) - ref["r"]) < 1e-10
        assert abs(float(ours.T_s[row]) - ref["T"]) < 1e-10
