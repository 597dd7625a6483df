"""Named starting points for the soap-film flow (Huang 2022, Sec. 3.6, Figs. 3.12-3.17).

:func:`build` returns a :class:`Scene` -- ``(state, air, params, description)`` -- ready for
:func:`~appearance_jax.soapfilm.flow.simulate`:

==============  ==================================================================================
``gravity``     eta = Gamma = 1 at rest, still air: gravity drains the film into horizontal
                colour bands, thin on top (Huang Figs. 3.12/3.13; the profile tends to
                eta ~ exp(-(g/M) cos theta), Huang Eq. 3.36).
``islands``     the gravity equilibrium (Huang Eq. 3.36, volume-normalised) with thin patches low on
                the bubble; Gamma keeps the equilibrium profile, so the Marangoni force per
                unit mass, M |grad Gamma| / eta, beats gravity where the film is thin: the
                patches are buoyant and rise as islands trailing rivers (Huang Fig. 3.14).
``blow``        eta = Gamma = 1; after ``blow_start`` (the gravity bands have formed) a rotating
                "ball of air" (blowing through a straw) swirls them into thin stripes (Huang
                Fig. 3.15).
``evaporate``   a noisy initial thickness, curl-noise air and evaporation: the film thins
                everywhere and the (thinnest) top fades to grey (Huang Fig. 3.17). The run stops
                when eta reaches 0 somewhere (``Result.stopped`` says so), as the thesis' does.
==============  ==================================================================================

Physical parameters (Huang Tables 3.1/3.2, via
:func:`~appearance_jax.soapfilm.thickness.dimensionless_numbers`): bubble radius ``R`` (m,
default 0.05), mean half thickness ``eta0`` (m, default 5e-7, i.e. a 1000 nm thick film) and
mean surfactant concentration ``Gamma0`` (mol/m^2, default 1.669e-7); with U = 1 m/s these give
M = 0.83, Cr = 2.1, g = 0.49. Time is in units of R / U (0.05 s at R = 5 cm).

**Chosen values.** The thesis states no parameters for the air, the noise, the patches or the
evaporation rate; the values here are ours, picked so that a run of a few seconds at the
default R shows the effect (constants below, all dimensionless unless stated):

* ``blow``: :class:`Swirl` (a :class:`~appearance_jax.soapfilm.air.Rotating` whose angular speed
  falls off away from its axis) about the camera axis -y: ``BLOW_OMEGA`` = 4 rad per R/U on the
  axis, times exp(-(1 - cos angle) / ``BLOW_WIDTH``), ``BLOW_WIDTH`` = 0.15 (the air is fastest,
  0.92 m/s, 0.38 rad from the axis), on from ``BLOW_START`` = 0.25 s (ramped over 0.5 R/U = 25 ms)
  to ``BLOW_STOP`` = inf. A rigid rotation of all the air only carries the film round; the shear
  of a localised swirl is what draws stripes. The air does not stop by default; a finite
  ``blow_stop`` lets the film spin down (with BiMocq^2
  distortion measured on the sphere such runs went unstable in the pole rows; measured in grid
  cells, as now, they settle: docs/soapfilm_flow.md).
* ``islands``: ``ISLANDS`` = 7 Gaussian patches (angular radius 0.12-0.25 rad) centred at
  theta in [0.65 pi, 0.92 pi], each thinning the film by 40-65 %, shaped by a 10 % noise.
  Gamma is not thinned with eta: with Gamma = eta (Gamma / eta = 1) the Marangoni flow
  -M grad(ln eta) fills the patches instead, and they vanish within 0.1 s (seen at 64x128).
* ``evaporate``: eta = 1 + 0.15 noise (frequency 6, :func:`~appearance_jax.soapfilm.air.noise`),
  curl-noise air of amplitude 0.3 U, frequency 4, and evaporation ``EVAPORATION`` = 0.01 eta_0
  per R/U (100 nm/s of half thickness at the defaults): the film loses 0.4 eta_0 in 2 s; the
  thinnest parts (the top, and the centres of the air's vortices, which thin fastest) go
  grey, and eta reaches 0 somewhere after roughly 2-3 s (2.7 s at 64x128).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..core.vec import Vec3, cross, dot
from .air import CurlNoise, Rotating, Still, noise
from .flow import FlowParams, State, check_state, rest_state, seconds_to_time
from .grid import SphereGrid, point
from .thickness import dimensionless_numbers, equilibrium_thickness

__all__ = ["SCENES", "AIR_FOR_SCENE", "Scene", "Swirl", "build", "numbers", "air_field",
           "BLOW_OMEGA", "BLOW_START", "BLOW_STOP", "EVAPORATION"]

#: the scene names, with one line each
SCENES = {
    "gravity": "uniform film at rest, still air: gravity bands (Huang Figs. 3.12/3.13)",
    "islands": "thin patches low on the bubble rise as islands and rivers (Huang Fig. 3.14)",
    "blow": "a rotating ball of air (straw) from 0.25 s on swirls the bands into stripes (Huang Fig. 3.15)",
    "evaporate": "noisy film, curl-noise air, evaporation: the top fades to grey (Huang Fig. 3.17)",
}
#: the air of each scene (a kind of :func:`air_field`)
AIR_FOR_SCENE = {"gravity": "none", "islands": "none", "blow": "blow", "evaporate": "curl"}

BLOW_AXIS = (0.0, -1.0, 0.0)  # towards the default camera (bubble.render looks from -y)
BLOW_OMEGA = 4.0  # rad per R/U at the axis; the fastest air, 0.92 U, is 0.38 rad from it
BLOW_WIDTH = 0.15
BLOW_START = 0.25  # s: the straw starts blowing
BLOW_STOP = float("inf")  # s: ... and does not stop (see the module text)
BLOW_RAMP = 0.5  # R/U: smooth on/off
CURL_AMPLITUDE = 0.3  # U
CURL_FREQUENCY = 4.0
NOISE_AMPLITUDE = 0.15  # relative thickness noise of "evaporate"
NOISE_FREQUENCY = 6.0
EVAPORATION = 0.01  # eta_0 per R/U
ISLANDS = 7


class Scene(NamedTuple):
    """A scene: ``state`` (:class:`~appearance_jax.soapfilm.flow.State`, dimensionless), ``air``
    (a hashable ``air(p, t)``), ``params`` (:class:`~appearance_jax.soapfilm.flow.FlowParams`)
    and a one-paragraph ``description`` stating the values used."""

    state: State
    air: object
    params: FlowParams
    description: str


def numbers(R=0.05, eta0=5e-7, Gamma0=1.669e-7):
    """Huang Table 3.2 at bubble radius ``R`` (m), mean half thickness ``eta0`` (m) and
    surfactant concentration ``Gamma0`` (mol/m^2), U = 1 m/s; values checked > 0 and finite."""
    for name, v in (("R", R), ("eta0", eta0), ("Gamma0", Gamma0)):
        if not (isinstance(v, (int, float, np.floating, np.integer)) and np.isfinite(v) and v > 0):
            raise ValueError(f"{name} = {v!r}: must be a finite number > 0")
    return dimensionless_numbers(R=float(R), eta0=float(eta0), Gamma0=float(Gamma0))


@dataclasses.dataclass(frozen=True)
class Swirl(Rotating):
    """A localised rotating ball of air: :class:`~appearance_jax.soapfilm.air.Rotating` whose
    angular speed falls off away from the axis, u_air = omega(t) exp(-(1 - a.p) / width) a x p.

    Each circle about ``a`` turns at its own rate (a differential rotation: tangent and
    divergence-free), so the film is sheared and its thickness wound into rings and stripes; a
    rigid rotation (``width`` = inf) only carries the film round. ``width``: the fall-off in
    1 - cos(angle from the axis) (0.15: 37 % of the axis' angular speed at 0.55 rad, 5 % at 1 rad).
    """

    width: float = 0.15

    def __post_init__(self):
        super().__post_init__()
        if not self.width > 0:  # inf allowed (rigid rotation)
            raise ValueError(f"width = {self.width!r}: must be > 0")

    def __call__(self, p: Vec3, t) -> Vec3:
        a = Vec3(*(jnp.asarray(c, p.x.dtype) for c in self.axis))
        fall = jnp.exp(-(1.0 - dot(a, p)) / jnp.asarray(self.width, p.x.dtype))
        return cross(a, p) * (fall * self.omega * self.strength(t))


def air_field(kind: str, *, R=0.05, seed: int = 0, blow_start: float = BLOW_START, blow_stop: float = BLOW_STOP):
    """The scenes' air of kind ``"none"``, ``"blow"`` or ``"curl"`` (values in the module text).

    Args:
        R: bubble radius (m), to convert the blowing times to dimensionless time.
        seed: seed of the curl noise.
        blow_start, blow_stop: when the straw starts and stops blowing (s; ``blow_stop`` inf:
            never).
    """
    if kind == "none":
        return Still()
    if kind == "blow":
        if not (0 <= blow_start < blow_stop):
            raise ValueError(f"blow_start = {blow_start!r}, blow_stop = {blow_stop!r}: need 0 <= start < stop")
        return Swirl(axis=BLOW_AXIS, omega=BLOW_OMEGA, start=float(seconds_to_time(blow_start, R)),
                     stop=float(seconds_to_time(blow_stop, R)), ramp=BLOW_RAMP, width=BLOW_WIDTH)
    if kind == "curl":
        return CurlNoise(seed=int(seed), amplitude=CURL_AMPLITUDE, frequency=CURL_FREQUENCY)
    raise ValueError(f"air = {kind!r}: must be one of none, blow, curl")


def _islands(grid: SphereGrid, g_over_M, seed, dtype):
    rng = np.random.default_rng(seed)
    theta, phi = grid.centres()
    p = point(jnp.asarray(theta), jnp.asarray(phi))
    eq = np.asarray(equilibrium_thickness(theta, g_over_M, "volume"), np.float64)
    eta = eq
    thin = np.zeros(grid.shape)
    for _ in range(ISLANDS):
        c = point(np.pi * rng.uniform(0.65, 0.92), rng.uniform(0.0, 2.0 * np.pi))
        cosd = np.asarray(p.x) * c.x + np.asarray(p.y) * c.y + np.asarray(p.z) * c.z
        d = np.arccos(np.clip(cosd, -1.0, 1.0))  # angular distance to the patch centre
        width = rng.uniform(0.12, 0.25)
        thin = np.maximum(thin, rng.uniform(0.4, 0.65) * np.exp(-0.5 * (d / width) ** 2))
    shape = 1.0 + 0.1 * np.asarray(noise(p, seed=seed + 1, frequency=8.0))
    eta = eta * (1.0 - np.clip(thin * shape, 0.0, 0.8))
    return rest_state(grid, jnp.asarray(eta, dtype), gamma=jnp.asarray(eq, dtype), dtype=dtype)


def build(name: str, grid: SphereGrid, *, R=0.05, eta0=5e-7, Gamma0=1.669e-7, seed: int = 0,
          blow_start: float = BLOW_START, blow_stop: float = BLOW_STOP, evaporation: float | None = None,
          dtype=None) -> Scene:
    """The scene ``name`` (one of :data:`SCENES`) on ``grid``.

    Args:
        name: "gravity", "islands", "blow" or "evaporate".
        grid: the :class:`~appearance_jax.soapfilm.grid.SphereGrid`.
        R, eta0, Gamma0: bubble radius (m), mean half thickness (m), mean surfactant
            concentration (mol/m^2) -> M, Cr, g (Huang Table 3.2).
        seed: seed of the random patches / noise / curl-noise air.
        blow_start, blow_stop: "blow": when the straw starts and stops blowing (s).
        evaporation: "evaporate": eta_0 lost per R/U (default :data:`EVAPORATION`); other
            scenes do not evaporate.
        dtype: of the fields (default: JAX's default float).

    Raises:
        ValueError: unknown name, or a non-positive R, eta0, Gamma0.
    """
    if name not in SCENES:
        raise ValueError(f"scene = {name!r}: must be one of {', '.join(SCENES)}")
    nums = numbers(R, eta0, Gamma0)
    dtype = jnp.result_type(float) if dtype is None else dtype
    head = (f"{name}: {SCENES[name]}. R = {R:g} m, eta0 = {eta0:g} m (film {2e9 * eta0:.0f} nm), "
            f"Gamma0 = {Gamma0:g} mol/m^2 -> M = {float(nums.M):.3g}, Cr = {float(nums.Cr):.3g}, "
            f"g = {float(nums.g):.3g}; time unit R/U = {R:g} s.")
    rate = 0.0
    air = air_field(AIR_FOR_SCENE[name], R=R, seed=seed, blow_start=blow_start, blow_stop=blow_stop)
    if name == "gravity":
        state = rest_state(grid, 1.0, dtype=dtype)
        more = "Start: eta = Gamma = 1, u = 0; still air."
    elif name == "islands":
        state = _islands(grid, float(nums.g_over_M), seed, dtype)
        more = (f"Start: volume-normalised equilibrium (g/M = {float(nums.g_over_M):.3g}) with {ISLANDS} thin "
                f"patches (40-65 % thinner, radius 0.12-0.25 rad) at theta 0.65-0.92 pi; Gamma = the unperturbed equilibrium; "
                f"still air; seed {seed}.")
    elif name == "blow":
        state = rest_state(grid, 1.0, dtype=dtype)
        more = (f"Start: eta = Gamma = 1, u = 0; air: a ball of air swirling about the view axis -y at "
                f"{BLOW_OMEGA:g} rad per R/U on the axis, falling off as exp(-(1 - cos angle) / {BLOW_WIDTH:g}) "
                f"(fastest 0.92 m/s, 0.38 rad from the axis), from {blow_start:g} s"
                + (f" to {blow_stop:g} s." if np.isfinite(blow_stop) else " on."))
    else:
        theta, phi = grid.centres()
        n = noise(point(jnp.asarray(theta), jnp.asarray(phi)), seed=seed, frequency=NOISE_FREQUENCY)
        eta = 1.0 + NOISE_AMPLITUDE * jnp.asarray(n, dtype)
        state = rest_state(grid, eta, dtype=dtype)
        rate = EVAPORATION if evaporation is None else float(evaporation)
        more = (f"Start: eta = Gamma = 1 + {NOISE_AMPLITUDE:g} noise (frequency {NOISE_FREQUENCY:g}, seed {seed}); "
                f"curl-noise air (amplitude {CURL_AMPLITUDE:g} U, frequency {CURL_FREQUENCY:g}); evaporation "
                f"{rate:g} eta0 per R/U ({rate * eta0 / R * 1e9:.3g} nm/s of half thickness); stops when eta "
                "reaches 0.")
    params = FlowParams.from_numbers(nums, evaporation=rate).check()
    check_state(grid, state)
    return Scene(state, air, params, f"{head} {more} (Noise, air and patch values are ours; the thesis gives "
                                     "none.)")
