"""Henyey-Greenstein against Mitsuba 3's ``hg`` phase function (an independent implementation).

Convention: Mitsuba's ``MediumInteraction3f.wi`` points away from the scattering point
(towards where the light came from), exactly like our ``wi``; its ``hg`` evaluates
``1 + g^2 + 2 g (wo . mi.wi)``, so ``eval_pdf(ctx, mi, wo)`` with ``mi.wi = wi`` must equal
``eval(Params(g), wi, wo)`` with no sign change. The forward-peak check below pins this
down independently of the random pairs (Mitsuba ``scalar_rgb`` computes in float32, hence
the 1e-4 relative tolerance).
"""

import math

import numpy as np
import pytest

from appearance_jax import testing
from appearance_jax.phase import henyey_greenstein as hg

mi = pytest.importorskip("mitsuba")

N_PAIRS = 1000
RTOL = 1e-4


@pytest.fixture(scope="module")
def mitsuba_scalar():
    mi.set_variant("scalar_rgb")
    return mi


def _mitsuba_eval(mit, g, wi, wo):
    """Mitsuba value and pdf at each pair (scalar variant: one call per pair)."""
    phase = mit.load_dict({"type": "hg", "g": float(g)})
    ctx = mit.PhaseFunctionContext(None)
    inter = mit.MediumInteraction3f()
    vals, pdfs = np.empty(len(wi)), np.empty(len(wi))
    for j, (a, b) in enumerate(zip(wi, wo)):
        inter.wi = mit.Vector3f(*a)
        value, pdf = phase.eval_pdf(ctx, inter, mit.Vector3f(*b))
        vals[j], pdfs[j] = value[0], pdf
    return vals, pdfs


def test_mitsuba_direction_convention(mitsuba_scalar):
    """For g = 0.9 both codes peak at wo = -wi with (1 + g) / (4 pi (1 - g)^2)."""
    wi = np.array([[0.0, 0.6, 0.8]])
    v_fwd, _ = _mitsuba_eval(mitsuba_scalar, 0.9, wi, -wi)
    v_back, _ = _mitsuba_eval(mitsuba_scalar, 0.9, wi, wi)
    np.testing.assert_allclose(v_fwd, 1.9 / (4 * math.pi * 0.01), rtol=RTOL)
    np.testing.assert_allclose(v_back, 0.1 / (4 * math.pi * 1.9**2), rtol=RTOL)


@pytest.mark.parametrize("g", (-0.7, -0.2, 0.3, 0.9))
def test_hg_matches_mitsuba(mitsuba_scalar, g):
    wi_v = testing.random_directions(100, N_PAIRS, "sphere")
    wo_v = testing.random_directions(101, N_PAIRS, "sphere")
    ours = np.asarray(hg.eval(hg.Params(g=g), wi_v, wo_v))[:, 0]
    our_pdf = np.asarray(hg.pdf(hg.Params(g=g), wi_v, wo_v))
    wi = np.stack([np.asarray(c) for c in wi_v], axis=-1)
    wo = np.stack([np.asarray(c) for c in wo_v], axis=-1)
    theirs, their_pdf = _mitsuba_eval(mitsuba_scalar, g, wi, wo)
    rel = np.abs(ours - theirs) / theirs
    print(f"g = {g}: max relative error vs Mitsuba {rel.max():.3g} over {N_PAIRS} pairs "
          f"(f in [{ours.min():.3g}, {ours.max():.3g}] 1/sr)")
    assert rel.max() <= RTOL
    np.testing.assert_allclose(our_pdf, their_pdf, rtol=RTOL)
    # the pairs must cover the lobe: values span more than the forward/backward ratio / 10
    assert ours.max() / ours.min() > 0.1 * ((1 + abs(g)) / (1 - abs(g))) ** 3
