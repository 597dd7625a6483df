"""core.model.LazyPresets: presets built on first access only, once; cloth's weave builders compile
nothing for concrete arguments and stay differentiable when traced."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core.model import LazyPresets


def test_lazy_presets_build_on_access_once():
    calls = []

    def build(name):
        calls.append(name)
        return {"name": name}

    m = LazyPresets(("a", "b"), build)
    assert list(m) == ["a", "b"] and len(m) == 2 and "a" in m and "c" not in m
    assert calls == []  # names only: nothing built
    assert m["b"] == {"name": "b"} and m["b"] is m["b"]
    assert calls == ["b"]
    with pytest.raises(KeyError):
        m["c"]
    assert dict(m) == {"a": {"name": "a"}, "b": {"name": "b"}} and calls == ["b", "a"]


def test_cloth_presets_are_lazy_and_equal_eager_build():
    from appearance_jax.bsdf import cloth
    from appearance_jax.bsdf.cloth import presets

    assert isinstance(cloth.PRESETS, LazyPresets)
    assert list(cloth.PRESETS) == list(presets.TABLE)
    p, q = cloth.PRESETS["silk_shot"], cloth.preset("silk_shot")
    for a, b in zip(jax.tree_util.tree_leaves(p), jax.tree_util.tree_leaves(q)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_weave_builders_numpy_when_concrete_jax_when_traced():
    from appearance_jax.bsdf.cloth import weave

    c = weave.stack([weave.join(weave.crossing(30.0), weave.plain(5.0)), weave.straight()])
    assert isinstance(c.offsets, np.ndarray) and c.offsets.shape == (2, 6)
    np.testing.assert_array_equal(c.offsets[1], [0, 0, 0, 0, 0, 0])
    np.testing.assert_array_equal(c.lengths[0], [1, 1, 1, 0, 1])

    def total_offset(a):
        s = weave.stack([weave.join(weave.crossing(a), weave.plain(5.0)), weave.straight()])
        return jnp.sum(s.offsets)

    # crossing(a).offsets = (-a, -a, a, a): d/da of its dot with (0, 1, 2, 3) is 4; of the sum, 0
    g = jax.grad(lambda a: jnp.sum(weave.crossing(a).offsets * jnp.arange(4.0)))(30.0)
    assert float(g) == pytest.approx(4.0)
    assert float(jax.grad(total_offset)(30.0)) == pytest.approx(0.0)
