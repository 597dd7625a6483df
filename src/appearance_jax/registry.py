"""Name -> model: the one list that the CLI, the fitters and the property tests read.

A model module ends with a ``MODEL = Model(...)`` record; add its import below.

Composite BSDFs (sums of lobes, :mod:`appearance_jax.bsdf.sum`) are named by joining
registered BSDF names with ``+``: ``get("rough_conductor+lambert")``. Those in
``_COMPOSITES`` are listed by :func:`names` / :func:`models` (and so by the CLI and the
property tests); any other ``+``-joined name of registered BSDFs is built on first use by
:func:`get` and cached (one model, one ``Params`` class per name), but not listed.
Whitespace around the parts is ignored (``"rough_conductor + lambert"`` is the same model).
"""

from __future__ import annotations

from .core.model import Model

_MODULES = (
    "appearance_jax.bsdf.lambert",
    "appearance_jax.bsdf.rough_conductor",
    "appearance_jax.bsdf.rough_dielectric",
    "appearance_jax.bsdf.rough_plastic",
    "appearance_jax.bsdf.iridescent",
    "appearance_jax.bsdf.snake",
    "appearance_jax.bsdf.cosmetics",
    "appearance_jax.bsdf.cloth",
    "appearance_jax.phase.henyey_greenstein",
    "appearance_jax.phase.hg_mixture",
    "appearance_jax.phase.sggx_flakes",
    "appearance_jax.bcsdf.chiang",
    "appearance_jax.bcsdf.marschner",
    "appearance_jax.bcsdf.sadeghi",
    "appearance_jax.bcsdf.huang",
)

# listed sums of lobes: Cook-Torrance specular + diffuse (the classical baseline for fitting
# measured BRDFs), and a coated diffuse base with an extra diffuse lobe
_COMPOSITES = (
    "rough_conductor+lambert",
    "rough_plastic+lambert",
)

_REGISTRY: dict[str, Model] | None = None
_BUILT: dict[str, Model] = {}  # composites built on demand by get()


def _load() -> dict[str, Model]:
    global _REGISTRY
    if _REGISTRY is None:
        import importlib

        from .bsdf.sum import sum_model

        reg: dict[str, Model] = {}
        for mod_name in _MODULES:
            model = importlib.import_module(mod_name).MODEL
            if model.name in reg:
                raise RuntimeError(f"duplicate model name {model.name!r} in {mod_name}")
            reg[model.name] = model
        for name in _COMPOSITES:
            if name in reg:
                raise RuntimeError(f"duplicate model name {name!r} in registry._COMPOSITES")
            reg[name] = sum_model(*(reg[part] for part in name.split("+")), name=name)
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
    parts = [part.strip() for part in name.split("+")]
    key = "+".join(parts)
    if key in reg:
        return reg[key]
    if key not in _BUILT:
        for part in parts:
            if part not in reg or "+" in part:
                raise _unknown(part, reg, name)
        from .bsdf.sum import sum_model

        _BUILT[key] = sum_model(*(reg[part] for part in parts), name=key)
    return _BUILT[key]


def names() -> list[str]:
    return list(_load())


def models() -> list[Model]:
    return list(_load().values())
