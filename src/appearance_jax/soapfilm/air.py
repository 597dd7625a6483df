"""Prescribed air velocities and smooth random fields for the soap-film flow (Huang 2022, Secs. 3.3,
3.6.3-3.6.4).

The air drag of Huang Eq. 3.17a, (Cr / eta)(u_air - u), needs the air velocity u_air on the film.
The thesis names two kinds without giving their parameters: a rotating "ball of air" (blowing
through a straw, Huang Fig. 3.15) and curl noise (Huang Fig. 3.17). Both are offered here as
hashable callables ``air(p, t) -> Vec3`` (p: unit vectors, t: dimensionless time, result: the
tangent air velocity in units of U), so that a simulation can take them as static arguments.

Curl noise is the surface curl p x grad(psi) of a smooth random potential psi; it is tangent and
divergence-free on the sphere. psi and :func:`noise` are sums of random plane waves
sin(k . p + c) restricted to the sphere (wave numbers |k| up to ``frequency``), which is smooth,
seamless across the poles and reproducible from an integer seed.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..core.vec import Vec3, cross
from .grid import components, point

__all__ = ["Still", "Rotating", "CurlNoise", "noise", "on_faces"]


@dataclasses.dataclass(frozen=True)
class Still:
    """No air motion."""

    def __call__(self, p: Vec3, t) -> Vec3:
        z = jnp.zeros_like(p.x)
        return Vec3(z, z, z)


@dataclasses.dataclass(frozen=True)
class Rotating:
    """A rotating "ball of air" inside the bubble: u_air = w(t) axis x p (Huang Fig. 3.15).

    Args:
        axis: rotation axis (normalised here); the default, horizontal, makes the air rise on
            one side and sink on the other.
        omega: angular speed (rad per unit of dimensionless time; the equator moves at omega U).
        start, stop: the air blows for ``start <= t < stop`` (dimensionless time), switched on
            and off smoothly over ``ramp``.
    """

    axis: tuple = (1.0, 0.0, 0.0)
    omega: float = 2.0
    start: float = 0.0
    stop: float = float("inf")
    ramp: float = 0.5

    def __post_init__(self):
        a = np.asarray(self.axis, dtype=float)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0:
            raise ValueError(f"axis = {self.axis!r}: must be a finite non-zero 3-vector")
        for name in ("omega", "ramp"):
            v = getattr(self, name)
            if not np.isfinite(v) or (name == "ramp" and v <= 0):
                raise ValueError(f"{name} = {v!r}: must be finite" + (" and > 0" if name == "ramp" else ""))
        object.__setattr__(self, "axis", tuple(float(x) for x in a / np.linalg.norm(a)))

    def strength(self, t):
        """w(t) / omega in [0, 1]: smooth on/off ramps."""
        on = jnp.clip((t - self.start) / self.ramp, 0.0, 1.0)
        off = 1.0 if not np.isfinite(self.stop) else jnp.clip((self.stop - t) / self.ramp, 0.0, 1.0)
        s = on * off
        return s * s * (3 - 2 * s)

    def __call__(self, p: Vec3, t) -> Vec3:
        a = Vec3(*(jnp.asarray(c, p.x.dtype) for c in self.axis))
        return cross(a, p) * (self.omega * self.strength(t))


def _waves(seed: int, n_waves: int, frequency: float):
    rng = np.random.default_rng(seed)
    k = rng.normal(size=(n_waves, 3))
    k *= (frequency * rng.uniform(0.3, 1.0, size=(n_waves, 1))) / np.linalg.norm(k, axis=1, keepdims=True)
    phase = rng.uniform(0, 2 * np.pi, size=n_waves)
    amp = rng.normal(size=n_waves) / np.sqrt(n_waves)
    return tuple(map(tuple, k)), tuple(phase), tuple(amp)


def _potential(waves, p: Vec3, t=0.0, speed=0.0):
    """psi(p) and grad psi (in R^3) of the plane-wave sum."""
    k, phase, amp = (np.asarray(a) for a in waves)
    psi = jnp.zeros_like(p.x)
    grad = Vec3(psi, psi, psi)
    for kk, c, a in zip(k, phase, amp):
        kk, c, a = [float(x) for x in kk], float(c), float(a)  # Python floats: keep p's dtype
        arg = kk[0] * p.x + kk[1] * p.y + kk[2] * p.z + c + speed * t
        psi = psi + a * jnp.sin(arg)
        grad = grad + Vec3(*(a * kc * jnp.cos(arg) for kc in kk))
    return psi, grad


@dataclasses.dataclass(frozen=True)
class CurlNoise:
    """Divergence-free random air flow u_air = amplitude * p x grad(psi) (Huang Fig. 3.17).

    Args:
        seed: integer seed of the random potential.
        amplitude: scale of the velocity (units of U; the r.m.s. speed is about amplitude *
            frequency / 2).
        frequency: largest wave number of the potential (features about 2 pi / frequency rad).
        n_waves: number of plane waves.
        drift: phase speed of the waves (per unit dimensionless time; 0 = steady air).
    """

    seed: int = 0
    amplitude: float = 0.5
    frequency: float = 4.0
    n_waves: int = 24
    drift: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.amplitude) and np.isfinite(self.frequency) and self.frequency > 0):
            raise ValueError(f"amplitude = {self.amplitude!r}, frequency = {self.frequency!r}: must be finite "
                             "(frequency > 0)")
        if int(self.n_waves) < 1:
            raise ValueError(f"n_waves = {self.n_waves!r}: must be >= 1")

    def __call__(self, p: Vec3, t) -> Vec3:
        _, grad = _potential(_waves(int(self.seed), int(self.n_waves), float(self.frequency)), p, t, self.drift)
        return cross(p, grad) * self.amplitude


def noise(p: Vec3, seed: int = 0, frequency: float = 6.0, n_waves: int = 32):
    """A smooth random scalar field on the sphere with zero mean and unit r.m.s. (approximately),
    for initial thickness perturbations (the thesis' Perlin noise, Huang Fig. 3.17)."""
    psi, _ = _potential(_waves(int(seed), int(n_waves), float(frequency)), p)
    return psi * float(np.sqrt(2.0))


def on_faces(grid, air, t, dtype):
    """``air`` at time ``t`` as (theta-face, phi-face) components on ``grid``."""
    out = []
    for (th, ph), pick in ((grid.u_theta_points(), 0), (grid.u_phi_points(), 1)):
        th, ph = jnp.asarray(th, dtype), jnp.asarray(ph, dtype)
        out.append(components(air(point(th, ph), t), th, ph)[pick])
    return out[0], out[1]

