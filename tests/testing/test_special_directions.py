"""Every registered model at the special directions (normal, antinormal, horizon, grazing
+-1e-7, all 36 pairs among them): finite values and pdfs, 0 below the horizon for
reflection BSDFs, finite gradients w.r.t. every floating-point field; float32 and float64
(appearance_jax.testing.check_special_directions). Expensive models run with small static
sample counts (the singular directions do not depend on them). The default run checks every
model in one dtype (float64 for the expensive ones, float32 for the others), -m slow in both."""

import numpy as np
import pytest

from appearance_jax import registry, testing
from appearance_jax.bsdf import lambert
from appearance_jax.core.model import Model, boundary, with_bands

# static settings that keep a model cheap (one eval and one grad per model and dtype)
CHEAP = {
    "cosmetics": dict(n_samples=4, max_bounces=8),
    "cloth": dict(n_samples=2),
    "cloth_weave": dict(n_samples=2),
    "huang_hair": dict(n_intervals=4, n_paths=1),
    "rock_dove": dict(n_phi=2, n_theta=1),
    # fewer ordinates and modes: the same code paths (interpolation to the directions, the tilt correction)
    "cosmetics_ordinates": dict(n_nodes=8, n_modes=6),
    "feather_fiber": dict(n_h=2, max_events=6, medulla=True),
    "feather": dict(n_h=2, max_events=6),
}

# Every model keeps one dtype in the default run, the other is a second case of the same code (slow).
# Models whose eval + gradient take more than ~10 s to compile here: float64 (the dtype of their other
# tests), float32 slow. The others: float32 (the grazing pairs are one float32 rounding off the
# horizon, and this is the only float32 run of their eval and gradients; their other tests run in
# float64), float64 slow.
HEAVY = {"huang_hair", "marschner_hair", "cosmetics", "cloth", "cloth_weave", "rough_plastic", "iridescent", "snake",
         "rock_dove", "cosmetics_ordinates", "feather_fiber",
         "feather"}
# sums whose components are checked on their own, and whose sum code rough_conductor+lambert covers
SLOW = {"rough_plastic+lambert"}


def _default_dtype(name):
    return "float64" if name in HEAVY else "float32"


MODELS = {m.name: m for m in registry.models()}
CASES = [pytest.param(name, dtype, id=f"{name}-{dtype}",
                      marks=[pytest.mark.slow] if name in SLOW or dtype != _default_dtype(name) else [])
         for name in sorted(MODELS) for dtype in ("float32", "float64")]


@pytest.mark.parametrize("name,dtype", CASES)
def test_special_directions(name, dtype, user_compiler_options):
    # tests/conftest.py runs the suite with XLA:CPU's legacy fusion emitters (faster to compile); this
    # check looks for NaN and infinities that depend on how the compiler fuses and contracts the
    # arithmetic, so it compiles with the emitters users get (XLA's default)
    model = MODELS[name]
    testing.assert_special_directions(model, model.Params(**CHEAP.get(name, {})), dtype=dtype,
                                      compiler_options=user_compiler_options)


def test_the_check_catches_nan_gradients_and_light_from_below():
    """A lambert whose value is 0 below the horizon but whose gradient is NaN there (a masked
    sqrt of a negative number), and one that reflects light from below: both fail."""
    import jax.numpy as jnp

    def nan_grad(p, wi, wo):
        up = (wi.z > 0) & (wo.z > 0)
        return jnp.where(with_bands(up), p.reflectance * with_bands(jnp.sqrt(wi.z * wo.z)) / jnp.pi, 0.0)

    def from_below(p, wi, wo):
        return jnp.broadcast_to(p.reflectance / jnp.pi, jnp.shape(wi.z) + (1,)) * jnp.ones((1,))

    P = lambert.Params
    for fn, what in ((nan_grad, "non-finite d/d.reflectance"), (from_below, "below the horizon")):
        m = Model(name="broken", kind="bsdf", Params=P, eval=boundary(fn, P), sample=None, pdf=None,
                  summary="broken on purpose", source="test")
        r = testing.check_special_directions(m, P(reflectance=0.5), dtype=np.float64)
        assert not r.passed and what in r.message, r.message
    assert testing.check_special_directions(lambert.MODEL, P(reflectance=0.5), dtype=np.float32).passed
