"""core.arrays: the array-library choice of host helpers and the stacking of like computations."""

import jax.numpy as jnp
import numpy as np
import pytest

from appearance_jax.core.arrays import namespace, stacked


def test_stacked_broadcasts_against_each_other_and_like():
    a, b = np.arange(3.0), np.asarray([[10.0], [20.0]])
    s = stacked(a, b)
    assert s.shape == (2, 2, 3)
    np.testing.assert_array_equal(s[0], np.broadcast_to(a, (2, 3)))
    np.testing.assert_array_equal(s[1], np.broadcast_to(b, (2, 3)))
    # ``like`` only widens the shape (a pytree: its leaves count, its values do not)
    s = stacked(1.0, 2.0, like={"p": np.zeros((4, 1)), "q": np.zeros(5)})
    assert s.shape == (2, 4, 5) and float(s[0].sum()) == 20.0 and float(s[1].sum()) == 40.0
    with pytest.raises(ValueError):
        stacked(np.zeros(3), np.zeros(4))


def test_namespace_follows_the_inputs():
    assert namespace(np.zeros(2), 1.0) is np
    assert namespace(np.zeros(2), jnp.zeros(2)) is jnp
