"""Name -> model: the one list that the CLI, the fitters and the property tests read.

The registry is the layer above every model: it imports the model modules (a model never
imports the registry) and lists their ``MODEL`` records. A new model module ends with a
``MODEL = Model(...)`` record; add its name and module to ``_ENTRIES`` below (imported on first use).

Composite BSDFs (sums of lobes, :mod:`appearance_jax.bsdf.sum`) are named by joining
registered BSDF names with ``+``: ``get("rough_conductor+lambert")``. Those in
``_COMPOSITES`` are listed by :func:`names` / :func:`models` (and so by the CLI and the
property tests); any other ``+``-joined name of registered BSDFs is built on first use by
:func:`get` and cached (one model, one ``Params`` class per name), but not listed.
Whitespace around the parts is ignored (``"rough_conductor + lambert"`` is the same model).
"""

from __future__ import annotations

import importlib

from .bsdf.sum import sum_model
from .core.model import Model

# (name, module under appearance_jax) in listing order. A model module is imported the first time its
# model is asked for, so a command that fits one model does not import (and build the module-level
# tables of) the other 22: ~0.7 s of a CLI fit's start on a 2-core machine. The module's ``MODEL``
# must carry the listed name (checked on import, and for every model by tests/core/test_registry.py).
_ENTRIES: tuple[tuple[str, str], ...] = (
    ("lambert", "bsdf.lambert"),
    ("rough_conductor", "bsdf.rough_conductor"),
    ("rough_dielectric", "bsdf.rough_dielectric"),
    ("rough_plastic", "bsdf.rough_plastic"),
    ("iridescent", "bsdf.iridescent"),
    ("snake", "bsdf.snake"),
    ("rock_dove", "bsdf.rock_dove"),
    ("feather", "bsdf.feather"),
    ("cosmetics", "bsdf.cosmetics"),
    ("cosmetics_ordinates", "bsdf.cosmetics_ordinates"),
    ("cloth", "bsdf.cloth"),
    ("cloth_weave", "bsdf.cloth.weaves"),
    ("henyey_greenstein", "phase.henyey_greenstein"),
    ("hg_mixture", "phase.hg_mixture"),
    ("sggx_flakes", "phase.sggx_flakes"),
    ("mie", "phase.mie"),
    ("tabulated_phase", "phase.tabulated"),
    ("chiang_hair", "bcsdf.chiang"),
    ("marschner_hair", "bcsdf.marschner"),
    ("sadeghi_hair", "bcsdf.sadeghi"),
    ("huang_hair", "bcsdf.huang"),
    ("feather_fiber", "bcsdf.feather_fiber"),
    ("cloth_thread", "bcsdf.thread"),
)
_WHERE = dict(_ENTRIES)

# listed sums of lobes: Cook-Torrance specular + diffuse (the classical baseline for fitting
# measured BRDFs), and a coated diffuse base with an extra diffuse lobe
_COMPOSITES = (
    "rough_conductor+lambert",
    "rough_plastic+lambert",
)

_NAMES: tuple[str, ...] = tuple(n for n, _ in _ENTRIES) + _COMPOSITES
if len(set(_NAMES)) != len(_NAMES):
    raise RuntimeError(f"duplicate model names in the registry: {sorted(n for n in _NAMES if _NAMES.count(n) > 1)}")
_LOADED: dict[str, Model] = {}  # registered models, imported on first use
_BUILT: dict[str, Model] = {}  # composites (listed or not) built on demand by get()


def _composite_params(name: str, values: dict):
    """Unpickle a composite's parameters: the registry's class of that name (see ``sum_model``)."""
    return get(name).Params(**values)


def _parse_sum(name: str) -> list[str]:
    """The component names of ``"a + b"`` (whitespace around the parts ignored)."""
    return [part.strip() for part in name.split("+")]


def _model(name: str) -> Model:
    """The registered (non-composite) model ``name``, importing its module on first use."""
    m = _LOADED.get(name)
    if m is None:
        m = importlib.import_module(f"{__package__}.{_WHERE[name]}").MODEL
        if m.name != name:
            raise RuntimeError(f"registry: appearance_jax.{_WHERE[name]}.MODEL is named {m.name!r}, listed as {name!r}")
        _LOADED[name] = m
    return m


def _build_sum(parts: list[str], whole: str) -> Model:
    for part in parts:
        if part not in _WHERE:  # a listed composite is no part either: parts hold no "+"
            raise _unknown(part, whole)
    key = "+".join(parts)
    return sum_model(*(_model(part) for part in parts), name=key, rebuild=_composite_params)


def _unknown(name: str, whole: str | None = None) -> KeyError:
    where = f" in {whole!r}" if whole is not None else ""
    return KeyError(f"unknown model {name!r}{where}; registered models: {', '.join(sorted(_NAMES))}")


def get(name: str) -> Model:
    """The model registered as ``name``; a KeyError lists the valid names.

    ``"a+b"`` (registered BSDF names joined by ``+``) is the sum of their lobes
    (:func:`appearance_jax.bsdf.sum.sum_model`), built once and cached; a component that is
    not a BSDF raises ``ValueError``. A model's module is imported on first use.
    """
    if isinstance(name, str) and name in _WHERE:
        return _model(name)
    if not isinstance(name, str) or "+" not in name:
        raise _unknown(name)
    parts = _parse_sum(name)
    key = "+".join(parts)
    if key not in _BUILT:
        _BUILT[key] = _build_sum(parts, name)
    return _BUILT[key]


def names() -> list[str]:
    """The listed model names (registered models and the listed composites), in registry order.
    Imports nothing."""
    return list(_NAMES)


def models() -> list[Model]:
    """The listed models, in registry order (imports every model module)."""
    return [get(n) for n in _NAMES]
