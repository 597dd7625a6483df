"""Name -> model: the one list that the CLI, the fitters and the property tests read.

The registry is the layer above every model: it imports the model modules (a model never
imports the registry) and lists their ``MODEL`` records. A new model module ends with a
``MODEL = Model(...)`` record; add it to ``_MODELS`` below.

Composite BSDFs (sums of lobes, :mod:`appearance_jax.bsdf.sum`) are named by joining
registered BSDF names with ``+``: ``get("rough_conductor+lambert")``. Those in
``_COMPOSITES`` are listed by :func:`names` / :func:`models` (and so by the CLI and the
property tests); any other ``+``-joined name of registered BSDFs is built on first use by
:func:`get` and cached (one model, one ``Params`` class per name), but not listed.
Whitespace around the parts is ignored (``"rough_conductor + lambert"`` is the same model).
"""

from __future__ import annotations

from .bcsdf import chiang, feather_fiber, huang, marschner, sadeghi, thread
from .bsdf import (cloth, cosmetics, cosmetics_ordinates, feather, iridescent, lambert, rock_dove, rough_conductor,
                   rough_dielectric, rough_plastic, snake)
from .bsdf.sum import sum_model
from .core.model import Model
from .phase import henyey_greenstein, hg_mixture, mie, sggx_flakes, tabulated

_MODELS: tuple[Model, ...] = (
    lambert.MODEL,
    rough_conductor.MODEL,
    rough_dielectric.MODEL,
    rough_plastic.MODEL,
    iridescent.MODEL,
    snake.MODEL,
    rock_dove.MODEL,
    feather.MODEL,
    cosmetics.MODEL,
    cosmetics_ordinates.MODEL,
    cloth.MODEL,
    cloth.weaves.MODEL,
    henyey_greenstein.MODEL,
    hg_mixture.MODEL,
    sggx_flakes.MODEL,
    mie.MODEL,
    tabulated.MODEL,
    chiang.MODEL,
    marschner.MODEL,
    sadeghi.MODEL,
    huang.MODEL,
    feather_fiber.MODEL,
    thread.MODEL,
)

# listed sums of lobes: Cook-Torrance specular + diffuse (the classical baseline for fitting
# measured BRDFs), and a coated diffuse base with an extra diffuse lobe
_COMPOSITES = (
    "rough_conductor+lambert",
    "rough_plastic+lambert",
)

_REGISTRY: dict[str, Model] | None = None
_BUILT: dict[str, Model] = {}  # composites built on demand by get()


def _composite_params(name: str, values: dict):
    """Unpickle a composite's parameters: the registry's class of that name (see ``sum_model``)."""
    return get(name).Params(**values)


def _parse_sum(name: str) -> list[str]:
    """The component names of ``"a + b"`` (whitespace around the parts ignored)."""
    return [part.strip() for part in name.split("+")]


def _build_sum(parts: list[str], reg: dict[str, Model], whole: str) -> Model:
    for part in parts:
        if part not in reg:  # a listed composite is no part either: parts hold no "+"
            raise _unknown(part, reg, whole)
    key = "+".join(parts)
    return sum_model(*(reg[part] for part in parts), name=key, rebuild=_composite_params)


def _load() -> dict[str, Model]:
    global _REGISTRY
    if _REGISTRY is None:
        reg: dict[str, Model] = {}
        for model in _MODELS:
            if model.name in reg:
                raise RuntimeError(f"duplicate model name {model.name!r} in registry._MODELS")
            reg[model.name] = model
        for name in _COMPOSITES:
            if name in reg:
                raise RuntimeError(f"duplicate model name {name!r} in registry._COMPOSITES")
            reg[name] = _build_sum(_parse_sum(name), reg, name)
        _REGISTRY = reg
    return _REGISTRY


def _unknown(name: str, reg, whole: str | None = None) -> KeyError:
    where = f" in {whole!r}" if whole is not None else ""
    return KeyError(f"unknown model {name!r}{where}; registered models: {', '.join(sorted(reg))}")


def get(name: str) -> Model:
    """The model registered as ``name``; a KeyError lists the valid names.

    ``"a+b"`` (registered BSDF names joined by ``+``) is the sum of their lobes
    (:func:`appearance_jax.bsdf.sum.sum_model`), built once and cached; a component that is
    not a BSDF raises ``ValueError``.
    """
    reg = _load()
    if name in reg:
        return reg[name]
    if not isinstance(name, str) or "+" not in name:
        raise _unknown(name, reg)
    parts = _parse_sum(name)
    key = "+".join(parts)
    if key in reg:
        return reg[key]
    if key not in _BUILT:
        _BUILT[key] = _build_sum(parts, reg, name)
    return _BUILT[key]


def names() -> list[str]:
    """The listed model names (registered models and the listed composites), in registry order."""
    return list(_load())


def models() -> list[Model]:
    """The listed models, in registry order."""
    return list(_load().values())
