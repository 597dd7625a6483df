import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core.model import boundary
from appearance_jax.core.params import describe, param, param_specs, params_class, static, validate


@params_class
class P:
    alpha: object = param(0.1, lo=0.0, lo_open=True, hi=4.0, unit="1", doc="roughness")
    albedo: object = param(0.5, lo=0.0, hi=1.0, doc="albedo", bands=True)
    beta: object = param(None, lo=0.0, doc="optional")
    kind: str = static("ggx", choices=("ggx", "beckmann"), doc="distribution")


def kernel(p, x):
    return p.alpha * x + jnp.sum(p.albedo)


ev = boundary(kernel, P)


def test_defaults_are_arrays_and_pytree_leaves():
    p = P()
    assert isinstance(p.alpha, jax.Array)
    leaves = jax.tree_util.tree_leaves(p)
    assert len(leaves) == 2  # beta=None is no leaf, kind is static
    p2 = jax.tree_util.tree_map(lambda v: v * 2, p)
    assert p2.kind == "ggx" and float(p2.alpha) == pytest.approx(0.2)


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(alpha=-0.1), r"P\.alpha = -0\.1 is outside the valid range \(0, 4\]"),
        (dict(alpha=0.0), r"P\.alpha = 0 is outside the valid range \(0, 4\]"),
        (dict(albedo=(0.2, 1.5, 0.3)), r"P\.albedo = 1\.5 is outside the valid range \[0, 1\]"),
        (dict(alpha=float("nan")), r"P\.alpha = nan is not finite"),
        (dict(beta=-1.0), r"P\.beta = -1"),
    ],
)
def test_bad_values_raise_naming_field_value_and_range(kw, match):
    with pytest.raises(ValueError, match=match):
        ev(P(**kw), 1.0)


def test_bad_static_choice_and_wrong_type():
    with pytest.raises(ValueError, match=r"P\.kind = 'phong' is not one of"):
        P(kind="phong")
    with pytest.raises(TypeError, match="expected parameters of type"):
        validate(object(), P)


def test_validation_is_skipped_for_tracers_and_jit_stays_usable():
    f = jax.jit(lambda a: ev(P(alpha=a), 2.0))
    assert float(f(0.5)) == pytest.approx(0.5 * 2.0 + 0.5)
    g = jax.grad(lambda p: ev(p, 3.0))(P())
    assert float(g.alpha) == pytest.approx(3.0)


def test_describe_lists_specs():
    rows = {r["name"]: r for r in describe(P)}
    assert rows["alpha"]["range"] == "(0, 4]" and rows["alpha"]["doc"] == "roughness"
    assert rows["kind"]["range"] == "{ggx, beckmann}"
    assert set(param_specs(P)) == {"alpha", "albedo", "beta", "kind"}
