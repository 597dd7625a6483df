"""Core conventions, defined once: vectors, frames, warps, special functions, parameters."""

from .vec import Vec3, vec3, dot, cross, norm, normalize  # noqa: F401
