"""Neural-BRDF **proxies** of the 78 MERL measured materials: smooth stand-ins for measured data.

What a proxy is
    A small network (6 -> 21 -> 21 -> 3, ReLU) fitted by Sztrajman et al. (2021, "Neural BRDF
    Representation and Importance Sampling", CGF 40(6)) to one MERL measurement (Matusik et
    al. 2003). It is **not** the measurement: it is a fit of it, with fitting error, and
    everything derived from it (tables, fits, plots) must say "proxy". It is useful because
    it is tiny (shipped in ``data/nbrdf/``, 300 kB for all 78 materials) and smooth (except
    at the mirror direction, see below) and differentiable, so a gonioreflectometer table can
    be synthesised on any angle grid.

Provenance
    ``data/nbrdf/nbrdf_merl.npz`` holds the trained networks of ``asztr/Neural-BRDF`` (commit
    e229dda3308c78f05e57dbc9455326884f766301, folder ``data/``; MIT licence,
    ``data/nbrdf/LICENSE-MIT.txt``) in one numpy archive, shipped unchanged;
    the underlying MERL measurements are CC-BY-SA-4.0. Attribute MERL (Matusik et al. 2003)
    and Sztrajman et al. (2021). See ``data/nbrdf/PROVENANCE.md``.

The network
    With Rusinkiewicz half/difference angles (phi_h = 0 by isotropy) of a pair (wi, wo)::

        x = [sin th_h, 0, cos th_h, sin th_d cos ph_d, sin th_d sin ph_d, cos th_d]
        f = max(exp(relu(relu(x W1 + b1) W2 + b2) W3 + b3) - 1, 0)      [1/sr, linear RGB]

    RGB is MERL's (scale factors 1/1500, 1.15/1500, 1.66/1500 already applied).

Conventions (checked)
    :func:`~appearance_jax.core.frame.to_half_diff` builds the difference vector exactly as the
    Neural-BRDF / MERL code does: d is **wi** rotated by -phi_h about z, then by -theta_h about
    y (right-handed rotations), phi_d = atan2(d_y, d_x). Its phi_d lies in (-pi, pi] while the
    networks saw [0, 2 pi); the input uses only cos and sin of phi_d, so that is immaterial and
    phi_d is fed as is. Checks: (1) in network coordinates (:func:`eval_proxy_half_diff`) the
    sanity values of SOURCES.txt at th_h = 0, th_d = 0.2, ph_d = +pi/2 are reproduced to every
    digit given (white-fabric 0.1143, 0.0804, 0.0490; blue-fabric 0.00746, 0.00824, 0.0187),
    whereas ph_d = -pi/2 gives 0.1129, 0.0791, 0.0478 and 0.00747, 0.00826, 0.0188, which do not
    round to them; (2) a pair built by hand (h tilted towards +x, wi on the +y side of the
    plane (normal, h)) gives phi_d = +pi/2 through :func:`eval_proxy`; (3) the networks' wild
    extrapolation lies where the training data had none, below the horizon: on the MERL grid
    (stride 3) a median of 6.5 % of the below-horizon nodes have exp(.) - 1 < 0 against 0 %
    (mean 0.8 %) of the above-horizon ones, and shifting phi_d by a quarter turn raises the
    latter to a median of 0.5 % (mean 2.4 %), so the horizon of this convention matches the
    training data's.

    The MERL data are folded by reciprocity, f(phi_d) = f(phi_d + pi), but the networks were
    trained on phi_d in [0, 2 pi) and learned that symmetry only approximately. Over the
    above-horizon MERL nodes (stride 5) the median relative difference between f(phi_d) and
    f(phi_d + pi) is 1.7 % (median over the 78 materials), reaching a median of 19 % for
    grease-covered-steel; f(phi_d) against f(-phi_d) (mirror symmetry) differs by 0.9 %.
    Swapping wi and wo is exactly phi_d -> phi_d + pi, so the proxy is **not exactly
    reciprocal**. On the default gonio grid the median relative difference between
    f(wi, wo) and f(wo, wi) is 1.7 % (median over materials), 0.8-2.0 % for the fabrics, and
    29 % (grease-covered-steel) and 21 % (ss440) at worst, mostly in dark off-specular
    regions. The networks are used as published, with no symmetrisation: averaging f(phi_d)
    and f(phi_d + pi) would move the proxy away from the published networks and their sanity
    values (white-fabric blue channel 0.0484 instead of 0.049), and folding phi_d into
    [0, pi) would put a discontinuity in the plane of incidence, where in-plane tables lie.
    ``tests/fit/tables/test_proxy.py`` measures the asymmetry on the gonio grid.

Mirror configuration (theta_h = 0)
    When wo is the mirror image of wi the half vector is the normal, phi_h is undefined and so
    is phi_d: the pairs (th_h = 0, th_d, phi_d) for all phi_d differ only by a rotation about
    the normal, and an isotropic BRDF takes one value on them. The networks do not: at
    th_h = 0, th_d <= 60 degrees their values spread over phi_d by a median of 12 % (max-min
    over max; 7-21 % for the fabrics, 63 % for grease-covered-steel), and f(0) and f(pi), the
    limits along the plane of incidence from its two sides, differ by a median of 7 %.
    to_half_diff would take phi_h from the rounding noise of h_x, h_y there (so a gonio
    table's mirror nodes would depend on rounding); :func:`eval_proxy` therefore uses
    phi_d = 0 when |h_xy| <= 100 eps (the limit from theta_o < theta_i in the plane of
    incidence). The proxy is thus discontinuous at the mirror direction by the network's
    own phi_d dependence there (the same holds for any approach to th_h = 0), and its
    gradient with respect to the directions grows like 1/theta_h near it.
    :func:`eval_proxy_half_diff` keeps the network's values at every (th_h, th_d, phi_d).

Clamping at zero
    exp(y) - 1 is negative for y < 0, and the networks do produce such values: down to
    -0.99 1/sr at half/difference angles whose directions lie below the horizon (pink-plastic,
    nylon: no training data there) and, above the horizon on the MERL grid (stride 5), down to
    -0.12 (pink-plastic), -0.10 (red-fabric) and -0.02 (white-paint). A BRDF is non-negative,
    and the upstream evaluation (the Mitsuba plugin and the PyTorch training code) applies
    ``max(., 0)`` too, so the proxy is clamped at 0; the clamp has zero gradient where active.
    Consequence: some proxies are *exactly* 0 on part of a grid (on the default gonio grid:
    black-obsidian 437, chrome-steel 320, red-metallic-paint 41, ss440 5,
    color-changing-paint1 2 of 945 values), which matters for fits in log space.

Limits
    The networks were trained with the cosine-weighted log loss
    mean |log(1 + f cos th_i) - log(1 + f_pred cos th_i)|. Where f cos th_i << 1 that is an
    *absolute* error on f cos th_i, so the relative accuracy of the proxy is best where
    f cos th_i is not tiny (highlights, bright diffuse materials, moderate angles) and poor
    for dark materials, dark off-specular regions and grazing incidence. The proxy also
    inherits the limits of MERL itself: isotropic, RGB only, one sample per material, and
    unreliable data near grazing angles.

All angles are in radians; BRDF values in 1/sr.
"""

from __future__ import annotations

import difflib
import functools

import jax
import jax.numpy as jnp
import numpy as np

from ...core.frame import half_vector, spherical_direction, to_half_diff
from ...core.vec import Vec3
from ...core.vec import where as vwhere
from . import grids
from .table import HORIZON_COS, Table

FABRICS = ("beige-fabric", "black-fabric", "blue-fabric", "dark-specular-fabric",
           "pink-fabric", "red-fabric", "white-fabric")

_FILE = ("nbrdf", "nbrdf_merl.npz")
_KEYS = ("W1", "b1", "W2", "b2", "W3", "b3")
# A node counts as below the horizon in a *table* when cos theta <= HORIZON_COS: theta = 90
# degrees converted from degrees gives cos = 6e-17, which is grazing, not a measurable direction
# (the same threshold as grids.half_diff_to_angles).
BELOW_HORIZON = "below horizon"


@functools.lru_cache(maxsize=1)
def _archive() -> dict:
    """All arrays of the shipped archive (float32 numpy), read once."""
    from ...data import path

    with path(*_FILE).open("rb") as fh, np.load(fh) as z:
        return {k: np.asarray(z[k]) for k in z.files}


def names() -> list[str]:
    """The 78 MERL material names with a proxy, sorted (e.g. ``"white-fabric"``)."""
    return sorted({k.split("/")[1] for k in _archive()})


def _numpy_weights(name: str) -> tuple:
    arc = _archive()
    if f"merl/{name}/W1" not in arc:
        close = difflib.get_close_matches(str(name), names(), n=5, cutoff=0.5)
        hint = f" Close matches: {', '.join(close)}." if close else ""
        raise KeyError(f"no Neural-BRDF proxy named {name!r}.{hint} "
                       "List all with appearance_jax.fit.tables.proxy.names().")
    return tuple(arc[f"merl/{name}/{k}"] for k in _KEYS)


@functools.lru_cache(maxsize=None)
def weights(name: str) -> tuple:
    """Network parameters of the proxy of MERL material ``name``: (W1, b1, W2, b2, W3, b3).

    A pytree of float32 ``jnp`` arrays, shapes (6, 21), (21,), (21, 21), (21,), (21, 3), (3,),
    exactly as stored (no conversion), cached per name. ``eval_proxy`` computes in the precision
    of the directions (float32 weights promote to float64 when the directions are float64).

    Raises:
        KeyError: unknown name; the message lists close matches.
    """
    return tuple(jnp.asarray(a) for a in _numpy_weights(name))


def _features(theta_h, theta_d, phi_d):
    """The network input (..., 6) from Rusinkiewicz angles (radians), phi_h = 0."""
    st_d = jnp.sin(theta_d)
    return jnp.stack([jnp.sin(theta_h), jnp.zeros_like(theta_h), jnp.cos(theta_h),
                      st_d * jnp.cos(phi_d), st_d * jnp.sin(phi_d), jnp.cos(theta_d)], axis=-1)


def _network(w, x):
    W1, b1, W2, b2, W3, b3 = w
    h = jax.nn.relu(x @ W1 + b1)
    h = jax.nn.relu(h @ W2 + b2)
    # expm1 == exp(.) - 1 of the published formula, without cancellation for dark values
    return jnp.maximum(jnp.expm1(h @ W3 + b3), 0.0)


def _as_float(a):
    """A jnp array of a floating dtype, keeping float32 inputs float32."""
    a = jnp.asarray(a)
    return a if jnp.issubdtype(a.dtype, jnp.floating) else a.astype(jnp.result_type(float))


def eval_proxy_half_diff(w, theta_h, theta_d, phi_d):
    """The proxy network in its own coordinates, shape ``broadcast(angles) + (3,)`` (RGB, 1/sr).

    Args:
        w: the weights pytree of :func:`weights`.
        theta_h, theta_d, phi_d: Rusinkiewicz angles in radians, phi_h = 0 (phi_d measured as in
            :func:`~appearance_jax.core.frame.to_half_diff`; any real value, it enters through
            cos and sin only).

    This is the network exactly as published (plus the clamp at 0), e.g. at MERL's nodes or at
    the sanity values of SOURCES.txt. Unlike :func:`eval_proxy` it keeps the network's phi_d
    dependence at theta_h = 0, where phi_d is not a property of the directions (see the
    module docstring). 0 where a direction is at or below the horizon.
    """
    th, td, pd = jnp.broadcast_arrays(_as_float(theta_h), _as_float(theta_d), _as_float(phi_d))
    # z of wi = R_y(theta_h) d and of its mirror image about h (from_half_diff's geometry)
    a, b = jnp.cos(td) * jnp.cos(th), jnp.sin(td) * jnp.cos(pd) * jnp.sin(th)
    valid = (a - b > 0) & (a + b > 0)
    f = _network(w, _features(th, td, pd))
    return jnp.where(valid[..., None], f, 0.0)


def eval_proxy(w, wi: Vec3, wo: Vec3):
    """BRDF of a Neural-BRDF proxy, shape ``broadcast(wi, wo) + (3,)`` (linear RGB, 1/sr).

    Args:
        w: the weights pytree of :func:`weights` (may be traced: differentiable in ``w``).
        wi, wo: unit directions (Vec3, local frame, z = normal), pointing away from the surface.

    Exactly 0 where ``wi.z <= 0`` or ``wo.z <= 0``, with finite (zero) gradients there. Pure and
    jittable; computes in the precision of the directions. At the mirror configuration
    (half vector on the normal, where phi_d is undefined) phi_d = 0 is used. Not exactly
    reciprocal (see the module docstring).
    """
    shape = jnp.broadcast_shapes(wi.shape, wo.shape)
    wi = wi.map(lambda a: jnp.broadcast_to(_as_float(a), shape))
    wo = wo.map(lambda a: jnp.broadcast_to(_as_float(a), shape))
    valid = (wi.z > 0) & (wo.z > 0)
    # Evaluate a harmless pair (both along the normal) where the result is discarded, so that
    # neither the value nor the gradient of the discarded branch can be NaN (wi = -wo has no
    # half vector); jnp.where alone would still propagate 0 * NaN into gradients.
    one, zero = jnp.ones(shape, wi.z.dtype), jnp.zeros(shape, wi.z.dtype)
    up = Vec3(zero, zero, one)
    wi, wo = vwhere(valid, wi, up), vwhere(valid, wo, up)
    theta_h, _, theta_d, phi_d = to_half_diff(wi, wo)
    # Mirror configuration: with h on the normal, phi_h (hence phi_d) comes from the rounding
    # noise of h_x, h_y, and the network is not phi_d-independent there as an isotropic BRDF
    # would be. Use phi_d = 0 (the limit along the plane of incidence from theta_o < theta_i)
    # so that mirror nodes are deterministic; 100 eps is well above the noise of |h_xy|.
    h = half_vector(wi, wo)
    tol = 100.0 * jnp.finfo(h.z.dtype).eps
    mirror = h.x * h.x + h.y * h.y <= tol * tol
    phi_d = jnp.where(mirror, jnp.zeros_like(phi_d), phi_d)
    f = _network(w, _features(theta_h, theta_d, phi_d))
    return jnp.where(valid[..., None], f, 0.0)


# ----------------------------------------------------------------------------------
# tables


def _evaluate(name: str, theta_i, phi_i, theta_o, phi_o) -> np.ndarray:
    """(N, 3) float64 proxy values at angle lists (radians), computed in float64 on the CPU."""
    with jax.enable_x64(True), jax.default_device(jax.devices("cpu")[0]):
        w = tuple(jnp.asarray(a, jnp.float64) for a in _numpy_weights(name))
        wi = spherical_direction(jnp.asarray(theta_i, jnp.float64), jnp.asarray(phi_i, jnp.float64))
        wo = spherical_direction(jnp.asarray(theta_o, jnp.float64), jnp.asarray(phi_o, jnp.float64))
        return np.asarray(_eval_jit(w, wi, wo), dtype=np.float64)


_eval_jit = jax.jit(eval_proxy)


def _table(name: str, theta_i, phi_i, theta_o, phi_o, source: str, in_plane_signed=None) -> Table:
    """Evaluate, mask below-horizon nodes (NaN, reason ``BELOW_HORIZON``) and build the Table."""
    ti, pi_, to, po = (np.asarray(a, np.float64).ravel() for a in np.broadcast_arrays(theta_i, phi_i, theta_o, phi_o))
    values = _evaluate(name, ti, pi_, to, po)
    above = (np.cos(ti) > HORIZON_COS) & (np.cos(to) > HORIZON_COS)
    mask = np.repeat(above[:, None], 3, axis=1)
    values = np.where(mask, values, np.nan)
    n_below = int((~mask).sum())
    masked = {BELOW_HORIZON: n_below} if n_below else {}
    if in_plane_signed is not None:
        return Table.in_plane(ti, in_plane_signed, values, mask=mask, quantity="brdf",
                              bands=("R", "G", "B"), source=source, masked=masked)
    return Table(theta_i=ti, phi_i=np.mod(pi_, 2 * np.pi), theta_o=to, phi_o=np.mod(po, 2 * np.pi),
                 values=values, mask=mask, quantity="brdf", bands=("R", "G", "B"), source=source,
                 masked=masked)


def _deg_list(a) -> str:
    """Grid axis for a table's source text: "0,20,40" or, when long and even, "-85..85 step 5"."""
    a = np.atleast_1d(np.asarray(a, float))
    step = np.diff(a)
    if a.size > 4 and np.allclose(step, step[0]) and step[0] > 0:
        return f"{a[0]:g}..{a[-1]:g} step {step[0]:g}"
    return ",".join(f"{v:g}" for v in a)


def proxy_table(name: str, grid: str = "gonio", *, stride: int = 5, theta_i_deg=None, theta_o_deg=None,
                dphi_deg=None) -> Table:
    """A synthetic BRDF table (quantity ``"brdf"``, 1/sr, bands R, G, B) from a Neural-BRDF **proxy**.

    Args:
        name: MERL material (see :func:`names`).
        grid: where to evaluate:

            - ``"merl"``: the MERL half/difference nodes every ``stride`` bins
              (:func:`~appearance_jax.fit.tables.grids.merl_angles`); nodes with a direction at or below
              the horizon are kept as rows but masked.
            - ``"in_plane"``: theta_i_deg (default 0, 15, ..., 75) x **signed** theta_o_deg
              (default -85 ... 85 step 5; > 0 forward/mirror side, < 0 retro side), built with
              :meth:`Table.in_plane`.
            - ``"gonio"``: an out-of-plane gonioreflectometer, theta_i_deg (default 0, 20, 40,
              60, 75) x theta_o_deg (default 0 ... 80 step 10) x dphi_deg = phi_o - phi_i
              (default 0 ... 180 step 30: the BRDF is isotropic, so half the azimuth circle
              suffices), phi_i = 0.
        stride: MERL bin stride (must divide 90 and 180), ``"merl"`` only.
        theta_i_deg, theta_o_deg, dphi_deg: grid axes in **degrees** (``None``: the defaults).

    The values are :func:`eval_proxy` at the table's directions (so on the MERL grid's
    theta_h = 0 nodes, the mirror configuration, they do not depend on phi_d; use
    :func:`eval_proxy_half_diff` for the network at the nodes themselves). Evaluated in float64
    on the CPU whatever the user's precision setting. Values at or below the
    horizon (cos theta <= 1e-12, e.g. theta = 90 degrees) are NaN, masked, and counted in
    ``Table.masked["below horizon"]`` (band entries, 3 per direction). For an arbitrary angle
    list use :func:`proxy_table_at`.
    """
    if grid == "merl":
        if theta_i_deg is not None or theta_o_deg is not None or dphi_deg is not None:
            raise ValueError("proxy_table: grid='merl' takes only stride, not theta_i_deg/theta_o_deg/dphi_deg")
        th, td, pd = grids.merl_angles(stride)
        ti, pi_, to, po, _ = grids.half_diff_to_angles(th.ravel(), td.ravel(), pd.ravel())
        return _table(name, ti, pi_, to, po, f"proxy:{name} (merl grid, stride {stride}, {th.size} nodes)")
    if grid == "in_plane":
        if dphi_deg is not None:
            raise ValueError("proxy_table: grid='in_plane' has no dphi_deg (signed theta_o_deg gives the side)")
        tid = (0, 15, 30, 45, 60, 75) if theta_i_deg is None else theta_i_deg
        tod = np.arange(-85, 86, 5) if theta_o_deg is None else theta_o_deg
        ti, to_signed = grids.in_plane_angles(tid, tod)
        # phi of wo as Table.in_plane stores it: pi on the forward side, 0 on the retro side
        po = np.where(to_signed >= 0, np.pi, 0.0)
        return _table(name, ti, np.zeros_like(ti), np.abs(to_signed), po,
                      f"proxy:{name} (in_plane grid, theta_i {_deg_list(tid)} deg x theta_o "
                      f"{_deg_list(tod)} deg)", in_plane_signed=to_signed)
    if grid == "gonio":
        tid = (0, 20, 40, 60, 75) if theta_i_deg is None else theta_i_deg
        tod = np.arange(0, 81, 10) if theta_o_deg is None else theta_o_deg
        dpd = np.arange(0, 181, 30) if dphi_deg is None else dphi_deg
        ti, pi_, to, po = grids.gonio_angles(tid, tod, dpd)
        return _table(name, ti, pi_, to, po,
                      f"proxy:{name} (gonio grid, theta_i {_deg_list(tid)} deg x theta_o {_deg_list(tod)} deg"
                      f" x dphi {_deg_list(dpd)} deg)")
    raise ValueError(f"proxy_table: grid = {grid!r}; use 'merl', 'in_plane' or 'gonio' "
                     "(or proxy_table_at for an explicit angle list)")


def proxy_table_at(name: str, theta_i, phi_i, theta_o, phi_o) -> Table:
    """A proxy table at a gonioreflectometer's own angle list (radians arrays, broadcast together).

    Same conventions as :func:`proxy_table` (float64, below-horizon rows masked); phi is stored
    modulo 2 pi.
    """
    n = np.broadcast(*(np.atleast_1d(a) for a in (theta_i, phi_i, theta_o, phi_o))).size
    return _table(name, *(np.atleast_1d(a) for a in (theta_i, phi_i, theta_o, phi_o)),
                  f"proxy:{name} (angle list, {n} directions)")
