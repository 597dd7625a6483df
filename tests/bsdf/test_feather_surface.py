"""bsdf.feather_surface (Padrón §5.6.2, spec M25 texture encoding): the mask's dispatch (vane = Eq. 5.4 with
the texel's barb angle, shaft = a two-sided coloured Lambertian, background = a null surface), its delta
masses and its sampler, on a texture rasterised and 8-bit encoded by bsdf.feather_texture."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.bsdf import feather, feather_surface as fs, feather_texture as ft
from appearance_jax.core.frame import spherical_direction

MED = (0.2, 0.45, 0.9)  # a blue medulla (three bands throughout: one compiled feather program)
P = feather.Params(n_h=4, medulla_albedo=MED)
WI, WO = spherical_direction(0.5, 0.2), spherical_direction(0.7, 2.5)
WO_BELOW = spherical_direction(2.3, 1.0)


@pytest.fixture(scope="module")
def texture():
    outline = ft.Outline(rachis=[[0, 0], [0, 10]], left=[[-2, 0], [-2, 10]], right=[[1.5, 0], [1.5, 10]],
                         shaft_width=(0.9, 0.6))
    b = np.concatenate([ft.barbs(outline, 24, 50.0, side=s, t_range=(0.0, 0.8)) for s in ("left", "right")])
    tex = ft.rasterize(outline, b, (12, 9), (-2.5, 2.0, -0.5, 10.5), samples_per_barb=32)
    angle, _, mask = ft.decode_rgb8(ft.encode_rgb8(tex, 4.0), 4.0)
    assert {0, 1, 2} <= set(np.unique(mask).tolist())
    return angle, mask


def test_each_texel_is_what_its_mask_says(texture):
    angle, mask = texture
    albedo = (0.7, 0.6, 0.4)
    for wo in (WO, WO_BELOW):
        f, se = fs.eval(P, angle, mask, WI, wo, shaft_albedo=albedo)
        vane = mask == ft.VANE
        # vane texels: the feather BSDF with that barb angle, the same estimator and key
        fv, sv = feather.eval(feather.Params(n_h=4, medulla_albedo=MED, barb_angle=angle), WI, wo)
        np.testing.assert_allclose(np.asarray(f)[vane], np.asarray(fv)[vane], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(np.asarray(se)[vane], np.asarray(sv)[vane], rtol=1e-12, atol=1e-15)
        # the shaft: albedo / pi with both directions on one side, 0 through it; the background: 0
        shaft_value = np.array(albedo) / math.pi if float(wo.z) > 0 else np.zeros(3)
        np.testing.assert_allclose(np.asarray(f)[mask == ft.SHAFT], np.broadcast_to(shaft_value, (int((mask == 1).sum()), 3)))
        assert np.all(np.asarray(f)[mask == ft.BACKGROUND] == 0.0)
        assert np.all(np.asarray(se)[mask != ft.VANE] == 0.0)
    # the shaft's default albedo is the medulla's d_m ([T:982])
    f, _ = fs.eval(P, angle, mask, WI, WO)
    np.testing.assert_allclose(np.asarray(f)[mask == ft.SHAFT][0], np.array(MED) / math.pi)
    # the vane turns with its texels: a different angle gives a different value
    assert np.abs(np.asarray(f)[mask == ft.VANE] - np.asarray(f)[mask == ft.VANE][0]).max() > 1e-4


def test_transmission_per_mask(texture):
    angle, mask = texture
    t = np.asarray(fs.transmission(P, angle, mask, WI))
    vane = mask == ft.VANE
    ref = feather.transmission(feather.Params(n_h=4, medulla_albedo=MED, barb_angle=angle), WI)
    np.testing.assert_allclose(t[vane], np.asarray(ref)[vane], rtol=1e-12)
    assert np.all(t[mask == ft.SHAFT] == 0.0) and np.all(t[mask == ft.BACKGROUND] == 1.0)
    assert 0.0 < t[vane].min() and t[vane].max() < 1.0


def test_sampler_per_mask_is_unbiased(texture):
    """Shaft: a cosine-distributed wo on the viewer's side with weight = albedo (E[wo.z] = 2/3 within 4.5 sigma);
    background: wo = -wi with weight 1; vane: feather.sample_events' event frequencies = the masking
    weights (4.5 sigma)."""
    angle, mask = texture
    n = 4096
    for kind in (ft.SHAFT, ft.BACKGROUND, ft.VANE):
        a = float(angle[mask == kind][0])
        A, M = jnp.full((n,), a), jnp.full((n,), kind)
        wo, w, ev = fs.sample_events(P, A, M, WI, jax.random.PRNGKey(kind), shaft_albedo=(0.7, 0.6, 0.4))
        wo_z, w, ev = np.asarray(wo.z), np.asarray(w), np.asarray(ev)
        if kind == ft.SHAFT:
            assert np.all(ev == fs.SHAFT_EVENT) and np.all(wo_z > 0)
            np.testing.assert_allclose(w, np.broadcast_to([0.7, 0.6, 0.4], w.shape))
            assert abs(wo_z.mean() - 2.0 / 3.0) < 4.5 * math.sqrt(1.0 / 18.0 / n)
        elif kind == ft.BACKGROUND:
            assert np.all(ev == 3) and np.all(w == 1.0)
            np.testing.assert_allclose(wo_z, -float(WI.z))
        else:
            m = feather.masking_of(feather.Params(n_h=4, medulla_albedo=MED, barb_angle=a), WI)
            want = np.append(np.asarray(m.weight), float(m.w_t))
            got = np.array([(ev == k).mean() for k in range(4)])
            assert np.all(np.abs(got - want) < 4.5 * np.sqrt(want * (1 - want) / n) + 1e-12), (got, want)
    # the viewer below the surface: the shaft reflects below
    wo, _, _ = fs.sample_events(P, jnp.zeros(n), jnp.full((n,), ft.SHAFT), WO_BELOW, jax.random.PRNGKey(5))
    assert np.all(np.asarray(wo.z) < 0)


def test_grazing_and_bad_input(texture):
    from appearance_jax.core.vec import Vec3
    angle, mask = texture  # (the texture's shape: the programs compiled above)
    grazing = Vec3(math.cos(0.3), math.sin(0.3), 0.0)
    f, se = fs.eval(P, angle, mask, grazing, WO)
    assert np.all(np.asarray(f) == 0.0) and np.all(np.isfinite(np.asarray(se)))
    assert np.all(np.asarray(fs.transmission(P, angle, mask, grazing)) == 0.0)
    with pytest.raises(ValueError, match="mask holds \\[3\\]"):
        fs.eval(P, 0.0, 3, WI, WO)
    with pytest.raises(ValueError, match="angle"):
        fs.transmission(P, float("nan"), 2, WI)
    with pytest.raises(ValueError, match="shaft_albedo"):
        fs.eval(P, 0.0, 1, WI, WO, shaft_albedo=1.5)
