"""Parameter spaces: bounded <-> unconstrained maps, band expansion, fixing, bounds flags."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax import registry
from appearance_jax.core.params import ParamSpec
from appearance_jax.fit.solve.transforms import EDGE, ParamSpace, _forward, _inverse


@pytest.mark.parametrize("spec", [ParamSpec(0.001, 2.0), ParamSpec(0.0, math.inf), ParamSpec(-math.inf, 1.0),
                                  ParamSpec(-math.inf, math.inf), ParamSpec(-1.0, 1.0, True, True)])
def test_round_trip_and_range(spec):
    lo = spec.lo if math.isfinite(spec.lo) else -5.0
    hi = spec.hi if math.isfinite(spec.hi) else 5.0
    x = np.linspace(lo + 0.01 * (hi - lo), hi - 0.01 * (hi - lo), 17)
    z = _inverse(spec, x)
    np.testing.assert_allclose(np.asarray(_forward(spec, jnp.asarray(z))), x, rtol=1e-12, atol=1e-12)
    # any z maps inside the declared range (large |z| included)
    zz = jnp.linspace(-30.0, 30.0, 101)
    xx = np.asarray(_forward(spec, zz))
    assert np.all(xx >= spec.lo) and np.all(xx <= spec.hi)
    # smooth: finite derivative everywhere; increasing on the branch _inverse maps to
    d = np.asarray(jax.vmap(jax.grad(lambda t: _forward(spec, t)))(jnp.linspace(-10.0, 10.0, 21)))
    assert np.all(np.isfinite(d))
    d = np.asarray(jax.vmap(jax.grad(lambda t: _forward(spec, t)))(jnp.asarray(z)))
    assert np.all(d > 0)


def test_start_on_a_bound_is_moved_inside():
    spec = ParamSpec(0.0, 1.0)
    z = _inverse(spec, np.array([0.0, 1.0]))
    assert np.all(np.isfinite(z))
    np.testing.assert_allclose(np.asarray(_forward(spec, jnp.asarray(z))), [EDGE, 1 - EDGE], rtol=1e-9)


def test_band_fields_expand_to_the_table_bands_and_labels():
    m = registry.get("rough_plastic")
    sp = ParamSpace(m.Params(), 3, fix=["eta"], band_names=("R", "G", "B"))
    assert sp.labels == ("alpha", "diffuse_reflectance[R]", "diffuse_reflectance[G]", "diffuse_reflectance[B]",
                         "specular_reflectance[R]", "specular_reflectance[G]", "specular_reflectance[B]")
    x = sp.x_start()
    p = sp.params_from_x(jnp.asarray(x))
    assert np.asarray(p.diffuse_reflectance).shape == (3,)
    assert float(p.eta) == 1.5  # fixed fields keep their start value
    np.testing.assert_allclose(sp.x_from_params(p), x)
    # the default specular_reflectance = 1 sits on its bound: its z is finite, moved inside by EDGE
    back = np.asarray(sp.x_from_z(jnp.asarray(sp.z_from_x(x))))
    np.testing.assert_allclose(back[:4], x[:4], rtol=1e-12)
    np.testing.assert_allclose(back[4:], 1 - EDGE, rtol=1e-12)


def test_fix_with_values_and_errors():
    m = registry.get("rough_conductor")
    sp = ParamSpace(m.Params(), 3, fix={"alpha": 0.3, "eta": (0.2, 0.9, 1.1)})
    assert float(sp.template.alpha) == pytest.approx(0.3)
    assert "alpha" not in sp.labels and not any(lab.startswith("eta") for lab in sp.labels)
    with pytest.raises(ValueError, match="unknown parameter.*alhpa"):
        ParamSpace(m.Params(), 3, fix=["alhpa"])
    with pytest.raises(ValueError, match="static"):
        ParamSpace(m.Params(), 3, fix=["distribution"])
    with pytest.raises(ValueError, match=r"alpha = 5 is outside the valid range"):
        ParamSpace(m.Params(), 3, fix={"alpha": 5.0})
    with pytest.raises(ValueError, match="nothing to fit"):
        ParamSpace(registry.get("lambert").Params(), 3, fix=["reflectance"])


def test_optional_fields_are_not_fitted():
    m = registry.get("rough_conductor")
    sp = ParamSpace(m.Params(), 3)
    assert not any(lab.startswith("alpha_v") for lab in sp.labels)  # alpha_v = None: isotropic
    sp2 = ParamSpace(m.Params(alpha_v=0.2), 3)
    assert "alpha_v" in sp2.labels


def test_random_starts_stay_in_range_and_at_bound_flags():
    m = registry.get("rough_conductor")
    sp = ParamSpace(m.Params(), 3, fix=["eta", "k"])
    z = sp.random_z(jax.random.PRNGKey(3), 64)
    x = np.asarray(sp.x_from_z(z))
    assert x.shape == (64, sp.size)
    assert np.all(x[:, 0] >= 0.001) and np.all(x[:, 0] <= 2.0)
    assert np.ptp(x[:, 0]) > 0.5  # the starts actually explore the range
    b = sp.at_bound(np.array([0.001, 0.5, 1.0, 1.0]))
    assert b.tolist() == [True, False, True, True]
