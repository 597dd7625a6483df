"""Fixed-size batches for the chiang_hair tests (test_chiang_hair.py, test_chiang_fast32.py).

Every near-field eval, pdf, sample and lobes call of those tests goes through :func:`batched`:
directions and the offset h (one per pair) flattened and padded to whole batches of N = 1200
pairs. XLA compiles one program per function, shape and static setting, so one batch shape
makes one program per function for all of those tests, and the same programs as
tests/validation/test_mitsuba_hair.py and test_export_mitsuba.py (1200 pairs, h per pair),
instead of one per caller's size (each a few seconds of XLA:CPU compilation in float64).
"""

import jax.numpy as jnp
import numpy as np

from appearance_jax.core.vec import Vec3

N = 1200


def batched(fn, p, wi, *rest, h=0.0, axis=0):
    """``fn(p, wi, *rest, h=h)`` for directions (and h) of any broadcast shape, flattened and
    padded (copies of the first pair) to whole batches of N, one call per batch, with h per
    pair (omitted for a far-field ``p``: h is integrated out). Outputs (arrays, tuples of
    arrays, Vec3) come back as numpy arrays with the batch shape at ``axis``. A ``rest`` that
    is not a Vec3 (sample's uniforms or key) is passed to every batch as it is: a key draws the
    same uniforms in every batch (one batch: as one call); uniforms need exactly one batch."""
    vecs = [wi] + [r for r in rest if isinstance(r, Vec3)]
    comps = [np.asarray(c, dtype=np.float64) for v in vecs for c in v] + [np.asarray(h, dtype=np.float64)]
    shape = np.broadcast_shapes(*(c.shape for c in comps))
    n = int(np.prod(shape))
    total = -(-n // N) * N
    assert total == N or not any(isinstance(r, tuple) for r in rest), "uniforms: one batch of N"
    flat = [np.broadcast_to(c, shape).ravel() for c in comps]
    flat = [jnp.asarray(np.concatenate([c, np.repeat(c[:1], total - n)])) for c in flat]
    outs = []
    for i in range(0, total, N):
        sl = [c[i:i + N] for c in flat]
        vs = iter([Vec3(*sl[3 * k:3 * k + 3]) for k in range(len(vecs))])
        first = next(vs)
        args = [next(vs) if isinstance(r, Vec3) else r for r in rest]
        outs.append(fn(p, first, *args) if p.far_field else fn(p, first, *args, h=sl[-1]))

    def join(parts):
        if parts[0] is None:
            return None
        if isinstance(parts[0], Vec3):
            return Vec3(*(join(list(c)) for c in zip(*(tuple(q) for q in parts))))
        if isinstance(parts[0], (tuple, list)):
            return type(parts[0])(join(list(c)) for c in zip(*parts))
        a = np.concatenate([np.asarray(q) for q in parts], axis=axis)
        a = np.take(a, np.arange(n), axis=axis)
        return a.reshape(a.shape[:axis] + shape + a.shape[axis + 1:])

    return join(outs)
