"""Composite BSDFs: the sum of registered BSDF lobes, f = f_1 + ... + f_K.

The classical baselines for fitting measured BRDFs (MERL, fabrics) are sums of a specular
microfacet lobe and a diffuse lobe, e.g. ``"rough_conductor+lambert"`` (Cook & Torrance
1982's specular + diffuse model; Ngan et al. 2005 fit such sums to MERL). They are built from
the registered models and are first-class models: a :class:`~appearance_jax.core.model.Model`
record with its own ``Params`` class, validated ``eval``/``sample``/``pdf``, listed by
:mod:`appearance_jax.registry` (``registry.get("a+b")`` builds any sum of registered BSDFs;
``"rough_conductor+lambert"`` and ``"rough_plastic+lambert"`` are listed).

    from appearance_jax import registry
    m = registry.get("rough_conductor+lambert")
    p = m.Params(alpha=0.2, specular_reflectance=0.5, reflectance=(0.3, 0.2, 0.1))
    f = m.eval(p, wi, wo)          # = rough_conductor f + lambert f, bands broadcast

or, for a model that is not registered, :func:`sum_model` (components as Model records).

**Parameters.** ``Params`` is a params class generated at run time whose fields are the
union of the components' fields, in component order, with the same metadata (default,
range, unit, meaning, bands; static fields too), so validation, the CLI's parameter tables
and the fitters treat it like any other model. Name collisions: a field of component ``k``
(0-based position in the sum) whose name is already taken by an earlier component is
renamed ``<component name>_<k>_<field>``, where non-identifier characters of the component
name (the ``+`` of a nested sum) become ``_``. For ``rough_conductor+rough_conductor`` the
second lobe's fields are ``rough_conductor_1_alpha``, ``rough_conductor_1_alpha_v``,
``rough_conductor_1_eta``, ... The first component never gets a prefix. The class records
its components' names (``Params.components``) and the mapping (``Params.field_map``: per
component, a tuple of (composite field, component field) pairs); ``params.split()`` returns
the components' own parameter objects. Composite fields are keyword-only. Cross-field
checks of the components (their ``_validate``) run on the components' sub-parameters.
Validation errors and reprs name the class ``<model name>.Params`` (e.g.
``rough_conductor+lambert.Params.alpha = -1 is outside the valid range [0.001, 2]``).
Parameters of a composite served by the registry pickle (they are rebuilt from
``registry.get(name)``); those of a model made by :func:`sum_model` alone can be copied but
not pickled (the generated class cannot be imported by name).

**Energy.** A sum of lobes conserves energy only if the components' albedos sum to at most
1; nothing enforces that (validation checks each field's own range only), so e.g. gold with
``specular_reflectance = 1`` (normal-incidence reflectance 0.96 in red) plus a Lambertian
of reflectance 0.5 reflects more red light than it receives. Keep the reflectance-like
parameters small enough when that matters.

**Sampling.** Lobe ``k`` is chosen with probability

    p_k = (1 - eps) w_k / sum_j w_j + eps / K,      eps = 1e-3

(defensive mixture, Hesterberg 1995: every lobe keeps a probability >= eps / K, so the
estimator stays unbiased for any parameters, even where the heuristic w_k is 0 for a lobe
that is not); ``w_k`` is the sum over the component's band-valued fields whose name ends in
``reflectance`` of their mean over the bands (lambert: reflectance; rough_conductor:
specular_reflectance; rough_plastic: diffuse_reflectance + specular_reflectance), 1 for a
component without such fields; if all w_k are 0, p_k = 1 / K. The chosen component samples
wo with its own sampler; then

    pdf(wi, wo)  = sum_k p_k pdf_k(wi, wo)
    weight       = (sum_k f_k(wi, wo)) |cos theta_o| / pdf(wi, wo)

(one-sample multiple importance sampling with the balance heuristic, Veach 1997, Sec. 9.2.4).
A sample fails (weight = 0, pdf = 0) when the chosen component's sampler fails.
``sample(params, wi, u_or_key)`` takes a PRNG key (split in two: the lobe choice, and the
key handed to every component's sampler) or a tuple of 1 + max_k n_k uniform arrays (the
first for the lobe choice, the rest handed to the components; n_k is what component k
takes: 2 for lambert and rough_conductor, 3 for rough_plastic and rough_dielectric).
If a component has no ``sample`` or ``pdf``, the composite has neither.

**Flags.** ``reciprocal`` = all components reciprocal; ``transmissive`` = any component
transmissive; no presets (a preset is a point in the composite's own parameter space; pass
``presets=`` to :func:`sum_model` to give some). ``summary`` and ``source`` list the
components'.

Cost: ``eval`` and ``pdf`` evaluate every component; ``sample`` runs every component's
sampler (branch-free: no data-dependent control flow under ``jit``) plus the composite
``eval`` and ``pdf`` at the chosen direction.
"""

from __future__ import annotations

import dataclasses
import re
import typing
from typing import Any, Mapping

import jax
import jax.numpy as jnp

from ..core.model import Model, as_bands, boundary, with_bands
from ..core.params import _META_KEY, ParamSpec, param_specs, params_class
from ..core.rng import is_prng_key
from ..core.vec import Vec3

#: probability mass spread evenly over the lobes whatever their weights (defensive mixture)
DEFENSIVE_FRACTION = 1e-3


# attributes of the generated Params class besides the fields
_RESERVED = frozenset({"split", "components", "field_map", "replace", "_validate", "__reduce_ex__"})


def _check_component(component) -> Model:
    if not isinstance(component, Model):
        raise ValueError(
            f"sum_model: component {component!r} is not a Model record (names of registered models are "
            "resolved by appearance_jax.registry.get('a+b'))"
        )
    if component.kind != "bsdf":
        raise ValueError(
            f"sum_model: component {component.name!r} is a {component.kind} model; only BSDFs (kind 'bsdf') "
            "can be summed"
        )
    return component


def _prefix(name: str, index: int) -> str:
    return f"{re.sub(r'[^0-9A-Za-z_]', '_', name)}_{index}_"


def _field_plan(models: list[Model]) -> tuple[list[dataclasses.Field], tuple[tuple[tuple[str, str], ...], ...], dict]:
    """The composite's fields (copies with the components' metadata), per component its
    (composite field, component field) pairs, and each composite field's annotation (its
    component's: Real, Bands, str, ...). Later colliding names get a prefix."""
    taken: dict[str, str] = {}  # composite field -> owner description (for error messages)
    fields: list[tuple[str, dataclasses.Field]] = []
    mapping = []
    types: dict[str, Any] = {}
    for k, m in enumerate(models):
        pairs = []
        hints = typing.get_type_hints(m.Params)
        for f in dataclasses.fields(m.Params):
            if _META_KEY not in f.metadata:
                continue
            new = f.name if f.name not in taken else _prefix(m.name, k) + f.name
            if new in taken:
                raise ValueError(
                    f"sum_model: field {f.name!r} of component {k} ({m.name}) renamed to {new!r} collides "
                    f"with the field {new!r} of {taken[new]}"
                )
            if new in _RESERVED:
                raise ValueError(f"sum_model: component {k} ({m.name}) has a field named {new!r}, which the "
                                 f"composite's Params uses for itself ({', '.join(sorted(_RESERVED))})")
            taken[new] = f"component {k} ({m.name})"
            kw: dict[str, Any] = dict(metadata=f.metadata, kw_only=True)
            if f.default is not dataclasses.MISSING:
                kw["default"] = f.default
            elif f.default_factory is not dataclasses.MISSING:
                kw["default_factory"] = f.default_factory
            fields.append((new, dataclasses.field(**kw)))
            pairs.append((new, f.name))
            types[new] = hints[f.name]
        mapping.append(tuple(pairs))
    return fields, tuple(mapping), types


def _make_params(name: str, models: list[Model], rebuild) -> type:
    """The composite's params class, labelled ``<name>.Params`` in validation errors and reprs."""
    fields, mapping, annotations = _field_plan(models)

    def split(self):
        """The components' parameter objects (one per component) built from this one."""
        return tuple(m.Params(**{c: getattr(self, s) for s, c in pairs}) for m, pairs in zip(models, mapping))

    def _validate(self):
        for k, (m, pairs) in enumerate(zip(models, mapping)):
            try:
                # constructing the component (concrete values) runs its checks, _validate included
                m.Params(**{c: getattr(self, s) for s, c in pairs})
            except ValueError as e:
                renamed = [f"{s} -> {c}" for s, c in mapping[k] if s != c]
                where = f" (fields renamed: {', '.join(renamed)})" if renamed else ""
                raise ValueError(f"{name}.Params, component {k} ({m.name}){where}: {e}") from e

    def __reduce_ex__(self, protocol):
        # pickle finds classes by module and name, which a generated class has not: whoever
        # owns a named class (the registry) hands in ``rebuild(name, values)``, an importable
        # function that returns its parameters (copy and deepcopy work for every composite;
        # pickling one made without ``rebuild`` fails)
        if rebuild is not None:
            values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
            return rebuild, (name, values)
        return object.__reduce_ex__(self, protocol)

    # the class body a ``class Params:`` statement would produce, for params_class (not
    # dataclasses.make_dataclass: it applies @dataclass itself, before params_class could
    # install the __post_init__ that the generated __init__ must call, and a second, frozen
    # @dataclass on its class raises "Cannot overwrite attribute __setattr__")
    ns: dict[str, Any] = {"__annotations__": annotations}
    ns.update(fields)
    ns.update(split=split, _validate=_validate, __reduce_ex__=__reduce_ex__,
              components=tuple(m.name for m in models), field_map=mapping,
              __doc__=f"Parameters of {name}: the union of the fields of {', '.join(m.name for m in models)}.")
    # validate() labels errors "<last part of __module__>.<__name__>": "rough_conductor+lambert.Params"
    ns["__module__"] = f"{__name__}.{name}"
    ns["__qualname__"] = f"{name}.Params"
    cls = type("Params", (), ns)
    return params_class(cls)


def _band_mean(v):
    return jnp.mean(as_bands(v), axis=-1)


def _lobe_weight(sub) -> jax.Array | float:
    """Heuristic w_k of a component: sum of the band means of its ``*reflectance`` fields, else 1."""
    w = None
    for fname, spec in param_specs(sub).items():
        if isinstance(spec, ParamSpec) and spec.bands and fname.endswith("reflectance"):
            v = getattr(sub, fname)
            if v is None:
                continue
            m = jnp.maximum(_band_mean(v), 0.0)
            w = m if w is None else w + m
    return 1.0 if w is None else w


def lobe_probabilities(models, subs) -> list[jax.Array]:
    """p_k of the lobe choice (module docstring), one array per component, broadcast together."""
    K = len(models)
    ws = [jnp.asarray(_lobe_weight(s), dtype=jnp.result_type(float)) for s in subs]
    ws = jnp.broadcast_arrays(*ws)
    tot = sum(ws[1:], ws[0])
    ok = tot > 0
    safe = jnp.where(ok, tot, 1.0)
    eps = DEFENSIVE_FRACTION
    return [jnp.where(ok, (1.0 - eps) * w / safe + eps / K, 1.0 / K) for w in ws]


def _select(index, options):
    """options[index] elementwise (index an int array, options a list of arrays)."""
    out = options[-1]
    for k in range(len(options) - 2, -1, -1):
        out = jnp.where(index == k, options[k], out)
    return out


def sum_model(*components: Model, name: str | None = None, presets: Mapping[str, Any] | None = None,
              rebuild=None) -> Model:
    """A :class:`Model` whose BSDF is the sum of ``components`` (Model records of kind 'bsdf').

    ``name`` defaults to the components' names joined by ``+``; it must not contain ``.``
    (validation errors are labelled ``<name>.Params.<field>``). Each call builds a new model
    with a new ``Params`` class; :func:`appearance_jax.registry.get` (``"a+b"``: names of
    registered BSDFs) caches one per name. ``rebuild(name, values)``, an importable function
    that returns this model's parameters from their field values, makes the generated
    ``Params`` picklable (the registry passes one). See the module docstring for the
    parameter naming rule, sampling and flags.
    """
    if not components:
        raise ValueError("sum_model: needs at least one component")
    models = [_check_component(c) for c in components]
    name = "+".join(m.name for m in models) if name is None else name
    if not name or "." in name:
        raise ValueError(f"sum_model: name {name!r} must be non-empty and contain no '.'")
    Params = _make_params(name, models, rebuild)

    def _sum_eval(subs, wi, wo):
        out = models[0].eval.kernel(subs[0], wi, wo)
        for m, s in zip(models[1:], subs[1:]):
            out = out + m.eval.kernel(s, wi, wo)
        return out

    def _eval(p, wi: Vec3, wo: Vec3):
        return _sum_eval(p.split(), wi, wo)

    def _pdf_with(subs, probs, wi, wo):
        out = probs[0] * models[0].pdf.kernel(subs[0], wi, wo)
        for m, s, pk in zip(models[1:], subs[1:], probs[1:]):
            out = out + pk * m.pdf.kernel(s, wi, wo)
        return out

    def _pdf(p, wi: Vec3, wo: Vec3):
        subs = p.split()
        return _pdf_with(subs, lobe_probabilities(models, subs), wi, wo)

    def _sample(p, wi: Vec3, u):
        subs = p.split()
        probs = lobe_probabilities(models, subs)
        if is_prng_key(u):
            k_lobe, k_comp = jax.random.split(u)
            u_comp, u_lobe = k_comp, None
        else:
            u = tuple(u)
            if len(u) < 1:
                raise ValueError(f"{name} sampler needs 1 uniform array for the lobe choice + those of its components")
            u_lobe, u_comp = u[0], u[1:]
        outs = []
        for k, (m, s) in enumerate(zip(models, subs)):
            try:
                outs.append(m.sample.kernel(s, wi, u_comp))
            except ValueError as e:
                if u_lobe is None or "uniform" not in str(e):
                    raise
                raise ValueError(f"{name}: the sampler takes 1 uniform array for the lobe choice followed by those "
                                 f"of the components ({len(u)} given); component {k} ({m.name}): {e}") from e
        shape = jnp.broadcast_shapes(jnp.shape(wi.z), *(jnp.shape(o[2]) for o in outs),
                                     *(jnp.shape(q) for q in probs))
        dtype = jnp.result_type(float)
        if u_lobe is None:
            u0 = jax.random.uniform(k_lobe, shape, dtype)
        else:
            u0 = jnp.broadcast_to(jnp.asarray(u_lobe, dtype), shape)
        # lobe index: number of cumulative probabilities <= u0 (the last lobe takes the rest)
        idx = jnp.zeros(shape, jnp.int32)
        cum = jnp.zeros(shape, dtype)
        for pk in probs[:-1]:
            cum = cum + pk
            idx = idx + (u0 >= cum).astype(jnp.int32)
        wo = Vec3(*(_select(idx, [jnp.broadcast_to(getattr(o[0], c), shape) for o in outs]) for c in "xyz"))
        pdf_chosen = _select(idx, [jnp.broadcast_to(o[2], shape) for o in outs])
        pdf = _pdf_with(subs, probs, wi, wo)
        ok = (pdf_chosen > 0) & (pdf > 0)
        f = _sum_eval(subs, wi, wo)
        scale = jnp.where(ok, jnp.abs(wo.z) / jnp.where(ok, pdf, 1.0), 0.0)
        return wo, f * with_bands(scale), jnp.where(ok, pdf, 0.0)

    can_sample = all(m.sample is not None and m.pdf is not None for m in models)
    sources = list(dict.fromkeys(m.source for m in models))
    return Model(
        name=name,
        kind="bsdf",
        Params=Params,
        eval=boundary(_eval, Params),
        sample=boundary(_sample, Params) if can_sample else None,
        pdf=boundary(_pdf, Params) if can_sample else None,
        summary="sum of lobes: " + " + ".join(f"{m.name} ({m.summary})" for m in models),
        source="; ".join(sources),
        reciprocal=all(m.reciprocal for m in models),
        transmissive=any(m.transmissive for m in models),
        presets=dict(presets or {}),
        # each component's own, under their composite names (no other component reads them)
        jacobian_apart=tuple(s for m, pairs in zip(models, Params.field_map) for s, c in pairs
                             if c in m.jacobian_apart),
        band_separable=all(m.band_separable for m in models),
    )


__all__ = ["sum_model", "lobe_probabilities", "DEFENSIVE_FRACTION"]
