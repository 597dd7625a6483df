"""Name -> model: the one list that the CLI, the fitters and the property tests read.

A model module ends with a ``MODEL = Model(...)`` record; add its import below.
"""

from __future__ import annotations

from .core.model import Model

_MODULES = (
    "appearance_jax.bsdf.lambert",
    "appearance_jax.bsdf.rough_conductor",
    "appearance_jax.bsdf.rough_dielectric",
    "appearance_jax.bsdf.rough_plastic",
    "appearance_jax.phase.henyey_greenstein",
    "appearance_jax.phase.hg_mixture",
)

_REGISTRY: dict[str, Model] | None = None


def _load() -> dict[str, Model]:
    global _REGISTRY
    if _REGISTRY is None:
        import importlib

        reg: dict[str, Model] = {}
        for mod_name in _MODULES:
            model = importlib.import_module(mod_name).MODEL
            if model.name in reg:
                raise RuntimeError(f"duplicate model name {model.name!r} in {mod_name}")
            reg[model.name] = model
        _REGISTRY = reg
    return _REGISTRY


def get(name: str) -> Model:
    """The model registered as ``name``; a KeyError lists the valid names."""
    reg = _load()
    if name not in reg:
        raise KeyError(f"unknown model {name!r}; registered models: {', '.join(sorted(reg))}")
    return reg[name]


def names() -> list[str]:
    return list(_load())


def models() -> list[Model]:
    return list(_load().values())
