"""Batched fits (vmap) and their sharding over devices (jax.sharding).

The two-device case runs in a subprocess because XLA reads
XLA_FLAGS=--xla_force_host_platform_device_count=2 only when it starts. The single-device
reference runs in the same subprocess (``devices=jax.devices()[:1]``: no mesh, one device), so
the test starts one Python and JAX instead of two and evaluates the model's table once.
"""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from appearance_jax import registry
from appearance_jax.fit.solve.batch import fit_batch
from appearance_jax.fit.tables.grids import in_plane_angles
from appearance_jax.fit.tables.table import Table

SCRIPT = textwrap.dedent("""
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from appearance_jax import registry
    from appearance_jax.fit.solve.batch import fit_batch
    from appearance_jax.fit.tables.grids import in_plane_angles
    from appearance_jax.fit.tables.table import Table

    m = registry.get("rough_conductor")
    ti, to = in_plane_angles([0, 30, 60], np.arange(-80, 81, 10))
    t = Table.in_plane(ti, to, np.ones((ti.size, 3)))
    wi, wo = t.directions()
    alphas = [0.1, 0.2, 0.3, 0.4, 0.5]  # K = 5: padded to 6 on two devices
    f = np.stack([np.asarray(m.eval(m.Params(alpha=a), wi, wo)) for a in alphas])
    noisy = f * (1 + 0.01 * np.random.default_rng(1).standard_normal(f.shape))
    out = {}
    for name, devices in (("one", jax.devices()[:1]), ("two", None)):  # None: every device, here 2
        r = fit_batch(m, t, noisy, fix=["eta", "k", "specular_reflectance"], devices=devices)
        out[name] = dict(n_devices=r.n_devices, x=r.x.tolist(), sigma=r.sigma.tolist(),
                         converged=r.converged.tolist())
    print(json.dumps(out))
""")


def _run(devices: int) -> dict:
    # the XLA_FLAGS of the run (conftest's fusion-emitter choice) are kept: the subprocess then
    # compiles as the suite does and shares its compilation cache
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={devices}".strip()
    env = dict(os.environ, XLA_FLAGS=flags, JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_sharded_batch_equals_single_device():
    res = _run(2)
    one, two = res["one"], res["two"]
    assert one["n_devices"] == 1 and two["n_devices"] == 2
    assert all(two["converged"]) and len(two["x"]) == 5  # padding dropped
    np.testing.assert_allclose(two["x"], one["x"], rtol=1e-9)
    np.testing.assert_allclose(two["sigma"], one["sigma"], rtol=1e-6)
    np.testing.assert_allclose(np.ravel(two["x"]), [0.1, 0.2, 0.3, 0.4, 0.5], rtol=5e-3)


def test_batch_items_with_their_own_masks_and_shape_errors():
    m = registry.get("lambert")
    ti, to = in_plane_angles([0, 40], np.arange(-60, 61, 30))
    t = Table.in_plane(ti, to, np.ones((ti.size, 3)))
    rho = np.array([[0.2, 0.3, 0.4], [0.8, 0.1, 0.5], [0.5, 0.5, 0.5]])
    values = np.broadcast_to(rho[:, None, :] / np.pi, (3, ti.size, 3)).copy()
    values[1, 0, 0] = np.nan  # missing in item 1 only
    r = fit_batch(m, t, values)
    np.testing.assert_allclose(r.x, rho, rtol=1e-8)
    item = r.item(1)
    assert item.n_valid == ti.size * 3 - 1
    np.testing.assert_allclose(item.x, rho[1], rtol=1e-8)
    with pytest.raises(ValueError, match=r"values must have shape \(K, 10, 3\)"):
        fit_batch(m, t, values[:, :5])
