"""appearance-jax: differentiable JAX micro-appearance models for inverse fitting."""

from .core.vec import Vec3, vec3  # noqa: F401

__version__ = "0.1.0"
