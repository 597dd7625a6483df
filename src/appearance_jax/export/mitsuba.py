"""Fitted parameters -> a Mitsuba 3 BSDF (a ``mitsuba.load_dict`` dict or an XML element).

    from appearance_jax.export import mitsuba as mx
    model, params = mx.from_params_json("out/fit/params.json")   # what `appearance-jax fit` wrote
    d = mx.to_mitsuba(model, params)          # {"type": "roughconductor", ...}: mitsuba.load_dict(d)
    xml = mx.to_mitsuba_xml(model, params)    # <bsdf type="roughconductor" ...>: mitsuba.load_string(xml)

Exportable models (:data:`EXPORTABLE`): ``lambert`` -> ``diffuse``, ``rough_conductor`` ->
``roughconductor``, ``rough_dielectric`` -> ``roughdielectric``, ``rough_plastic`` ->
``roughplastic``, ``chiang_hair`` -> ``hair``, and sums of the first four (``"a+b"``) -> nested
``blendbsdf``. Every parameter's mapping (property, units, frames, tables) is tabulated in
``docs/export.md``; the conventions were established by the pointwise comparisons in
``tests/validation/test_mitsuba_*.py``.

**Exact or refused.** An export is *exact* when Mitsuba's BSDF evaluates the same function as
ours, up to Mitsuba's own implementation approximations of the same model (float32; Walter et
al. 2007, Eq. 27's rational Beckmann G1, < 0.35 % per factor; the hair plugin's I0 series,
< 1 %; for ``rough_plastic`` with ``tables="mitsuba"`` Mitsuba's own coat-table quadrature,
<= 6e-4 in f for GGX, <= 5.5e-3 for Beckmann). A setting Mitsuba has no equivalent for is a
*difference* (:func:`differences`): the height-correlated Smith G2 (``shadowing="correlated"``,
our default; Mitsuba's microfacet plugins use the separable G1(wi) G1(wo)) and
``rough_plastic``'s ``tables="accurate"`` (Mitsuba precomputes its own coat tables, whose
R_int is ~1 % low). :func:`to_mitsuba` raises :class:`ExportError` naming them unless
``approximate=True``; refit with ``--param shadowing=separable`` (and ``tables=mitsuba``)
for an exact export.

**Sums.** ``blendbsdf`` is the convex mix (1 - w) f_0 + w f_1, so the sum f_1 + ... + f_K is
written as the mix with weights c_k (sum 1) of the lobes scaled by 1/c_k. The scale goes into
each lobe's reflectance fields, on which f depends linearly (lambert ``reflectance``,
rough_conductor ``specular_reflectance``, rough_plastic ``diffuse_reflectance`` and
``specular_reflectance`` with ``nonlinear=False``; rough_dielectric's Mitsuba-only
``specular_reflectance`` and ``specular_transmittance``, 1 for ours). Mitsuba refuses RGB
reflectances above 1 (a single grey value may exceed 1), so with m_k the largest *coloured*
reflectance of lobe k and M_k its largest reflectance of any kind,

    c_k = m_k + (1 - sum_j m_j) M_k / sum_j M_j,

which keeps every scaled coloured value <= 1; it exists when sum_j m_j < 1 (or = 1 with no
grey-only lobe), else the sum is refused. A lobe whose reflectances are all 0 is 0 and is left
out. A ``nonlinear=True`` rough_plastic is not linear in its albedo and cannot be scaled.

Bands: a band field with one value, or three equal values, becomes a Mitsuba float; three
values become ``{"type": "rgb"}`` (linear sRGB, the bands of the library's RGB tables). Other
band counts (spectral fits) and spatially varying (array) parameters are refused.
"""

from __future__ import annotations

import json
import math
import os
import re
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from .. import registry
from ..core.files import FileProblem, read_regular_file
from ..core.model import Model
from ..core.params import param_specs

__all__ = ["EXPORTABLE", "ExportError", "differences", "from_params_json", "read_params_json", "to_mitsuba",
           "to_mitsuba_xml", "dict_to_xml"]

#: our model -> Mitsuba 3 plugin
EXPORTABLE = {
    "lambert": "diffuse",
    "rough_conductor": "roughconductor",
    "rough_dielectric": "roughdielectric",
    "rough_plastic": "roughplastic",
    "chiang_hair": "hair",
}
#: models that may be summed ("a+b" -> blendbsdf)
SUMMABLE = ("lambert", "rough_conductor", "rough_dielectric", "rough_plastic")
#: the reflectance fields that scale each summable model's f linearly (see the module docstring)
_SCALED = {
    "lambert": ("reflectance",),
    "rough_conductor": ("specular_reflectance",),
    "rough_plastic": ("diffuse_reflectance", "specular_reflectance"),
    "rough_dielectric": (),  # Mitsuba's specular_reflectance / specular_transmittance, 1 for ours
}
#: largest params.json read (a fit's record is a few KB)
MAX_RECORD_BYTES = 16 * 2**20


class ExportError(ValueError):
    """A model or parameter setting that cannot be written as a Mitsuba BSDF (or a bad params.json)."""


def _exportable_text() -> str:
    return (", ".join(EXPORTABLE) + f", and sums of {', '.join(SUMMABLE)} joined by '+' "
            "(e.g. rough_conductor+lambert)")


def _resolve(model) -> Model:
    if isinstance(model, Model):
        return model
    if isinstance(model, str):
        try:
            return registry.get(model)
        except (KeyError, ValueError) as e:
            msg = e.args[0] if e.args else str(e)
            raise ExportError(f"model {model!r}: {msg}") from None
    raise TypeError(f"model must be a model name or a Model record, got {type(model).__qualname__}")


def _leaves(model: Model, params) -> list[tuple[str, object]]:
    """(component name, its Params) of every lobe, nested sums flattened."""
    names = getattr(type(params), "components", None)
    if names is None:
        if model.name not in EXPORTABLE:
            raise ExportError(f"model {model.name!r} has no Mitsuba 3 equivalent; exportable: {_exportable_text()}")
        return [(model.name, params)]
    out = []
    for name, sub in zip(names, params.split()):
        comp = registry.get(name)
        if comp.name not in SUMMABLE and getattr(type(sub), "components", None) is None:
            raise ExportError(f"model {model.name!r}: its component {comp.name!r} has no Mitsuba 3 equivalent "
                              f"in a sum; exportable: {_exportable_text()}")
        out += _leaves(comp, sub)
    return out


def _checked(model, params) -> tuple[Model, list[tuple[str, object]]]:
    m = _resolve(model)
    if m.name not in EXPORTABLE and "+" not in m.name:
        raise ExportError(f"model {m.name!r} has no Mitsuba 3 equivalent; exportable: {_exportable_text()}")
    if not isinstance(params, m.Params):
        raise TypeError(f"params is a {type(params).__qualname__}; expected {m.name}.Params")
    return m, _leaves(m, params)


def differences(model, params) -> list[str]:
    """What Mitsuba cannot reproduce of this model and these parameters (empty: exact export).

    ``model`` is a registered name or a :class:`~appearance_jax.core.model.Model`; ``params``
    its ``Params``. Each entry names the component, the field and its value, what Mitsuba does
    instead and how large the difference is (measured, ``docs/export.md``).
    """
    _, leaves = _checked(model, params)
    out = []
    for name, p in leaves:
        if name in ("rough_conductor", "rough_dielectric", "rough_plastic") and p.shadowing != "separable":
            out.append(f"{name}.shadowing = {p.shadowing!r}: Mitsuba's {EXPORTABLE[name]} uses the separable Smith "
                       "G2 = G1(wi) G1(wo), which is smaller than the height-correlated G2 (most at grazing angles "
                       "and high roughness; docs/export.md gives the measured size)")
        if name == "rough_plastic" and p.tables != "mitsuba":
            out.append(f"rough_plastic.tables = {p.tables!r}: Mitsuba's roughplastic precomputes its own coat tables "
                       "(R_int ~1 % low, the diffuse term up to ~4.5 % low; docs/microfacet.md)")
    return out


def _float64(v) -> np.ndarray:
    """float64 values; float32 ones by their shortest decimal (0.2, not 0.20000000298...)."""
    a = np.asarray(v)
    if a.dtype == np.float32:
        return np.vectorize(lambda x: float(str(np.float32(x))), otypes=[np.float64])(a)
    return np.asarray(a, dtype=np.float64)


def _scalar(label: str, v) -> float:
    a = _float64(v)
    if a.size != 1:
        raise ExportError(f"{label} has shape {a.shape}: a Mitsuba BSDF property takes one value "
                          "(spatially varying parameters are not exported)")
    return float(a.reshape(()))


def _band_values(label: str, v) -> np.ndarray:
    a = _float64(v)
    if a.ndim == 0:
        return a.reshape(1)
    if a.ndim != 1:
        raise ExportError(f"{label} has shape {a.shape}: a Mitsuba BSDF property takes 1 or 3 values "
                          "(spatially varying parameters are not exported)")
    if a.shape[0] not in (1, 3):
        raise ExportError(f"{label} has {a.shape[0]} bands: Mitsuba's RGB properties take 1 or 3 values "
                          "(R, G, B); spectral fits are not exported")
    return a


def _spectrum(label: str, v, scale: float = 1.0):
    """A float (one value, or equal values) or an rgb dict, times ``scale``."""
    a = _band_values(label, v) * scale
    if np.all(a == a[0]):
        return float(a[0])
    return {"type": "rgb", "value": [min(float(x), 1.0) if 1.0 < x < 1.0 + 1e-9 else float(x) for x in a]}


def _alpha(label: str, p, d: dict) -> None:
    if getattr(p, "alpha_v", None) is None:
        d["alpha"] = _scalar(f"{label}.alpha", p.alpha)
    else:
        d["alpha_u"] = _scalar(f"{label}.alpha", p.alpha)
        d["alpha_v"] = _scalar(f"{label}.alpha_v", p.alpha_v)


def _leaf_dict(name: str, p, scale: float = 1.0) -> dict:
    if name == "lambert":
        return {"type": "diffuse", "reflectance": _spectrum("lambert.reflectance", p.reflectance, scale)}
    if name == "rough_conductor":
        d = {"type": "roughconductor", "distribution": p.distribution}
        _alpha(name, p, d)
        d["eta"] = _spectrum(f"{name}.eta", p.eta)
        d["k"] = _spectrum(f"{name}.k", p.k)
        d["specular_reflectance"] = _spectrum(f"{name}.specular_reflectance", p.specular_reflectance, scale)
        return d
    if name == "rough_dielectric":
        d = {"type": "roughdielectric", "distribution": p.distribution}
        _alpha(name, p, d)
        eta = _scalar(f"{name}.eta", p.eta)  # int_ior / ext_ior; keep both >= 1
        d.update(int_ior=eta, ext_ior=1.0) if eta >= 1.0 else d.update(int_ior=1.0, ext_ior=1.0 / eta)
        if scale != 1.0:
            d.update(specular_reflectance=scale, specular_transmittance=scale)
        return d
    if name == "rough_plastic":
        if scale != 1.0 and p.nonlinear:
            raise ExportError("rough_plastic.nonlinear = True in a sum: its diffuse term rho / (1 - rho R_int) is "
                              "not linear in rho, so blendbsdf cannot carry the sum exactly (refit with "
                              "nonlinear=False, or export the lobes separately)")
        return {"type": "roughplastic", "distribution": p.distribution,
                "alpha": _scalar(f"{name}.alpha", p.alpha), "int_ior": _scalar(f"{name}.eta", p.eta),
                "ext_ior": 1.0, "nonlinear": bool(p.nonlinear),
                "diffuse_reflectance": _spectrum(f"{name}.diffuse_reflectance", p.diffuse_reflectance, scale),
                "specular_reflectance": _spectrum(f"{name}.specular_reflectance", p.specular_reflectance, scale)}
    if name == "chiang_hair":
        return {"type": "hair", "sigma_a": _spectrum(f"{name}.sigma_a", p.sigma_a),
                "int_ior": _scalar(f"{name}.eta", p.eta), "ext_ior": 1.0,
                "longitudinal_roughness": _scalar(f"{name}.beta_m", p.beta_m),
                "azimuthal_roughness": _scalar(f"{name}.beta_n", p.beta_n),
                "scale_tilt": math.degrees(_scalar(f"{name}.alpha", p.alpha))}
    raise AssertionError(name)  # _leaves admits only EXPORTABLE names


def _lobe_maxima(name: str, p) -> tuple[float, float]:
    """(largest coloured reflectance m, largest reflectance of any kind M) of a lobe's scaled fields."""
    if name == "rough_dielectric":
        return 0.0, 1.0
    m = big = 0.0
    for field in _SCALED[name]:
        a = _band_values(f"{name}.{field}", getattr(p, field))
        big = max(big, float(a.max()))
        if not np.all(a == a[0]):
            m = max(m, float(a.max()))
    return m, big


def _blend(leaves) -> dict:
    maxima = [_lobe_maxima(n, p) for n, p in leaves]
    kept = [(n, p, m, big) for (n, p), (m, big) in zip(leaves, maxima) if big > 0.0]
    if not kept:  # every lobe is 0: so is the sum
        return _leaf_dict(*leaves[0])
    if len(kept) == 1:
        return _leaf_dict(kept[0][0], kept[0][1])
    sum_m = sum(k[2] for k in kept)
    sum_big = sum(k[3] for k in kept)
    c = [m + (1.0 - sum_m) * big / sum_big for _, _, m, big in kept]
    if sum_m > 1.0 or min(c) <= 0.0:
        parts = ", ".join(f"{n} {m:.4g}" for n, _, m, _ in kept)
        raise ExportError(
            "blendbsdf mixes its BSDFs convexly, so a sum is written with each lobe's reflectance scaled by "
            f"1/c_k (sum of c_k = 1); Mitsuba refuses RGB reflectances above 1, and the lobes' largest coloured "
            f"reflectances ({parts}) sum to {sum_m:.4g} >= 1, so no such weights exist")
    dicts = [_leaf_dict(n, p, 1.0 / ck) for (n, p, _, _), ck in zip(kept, c)]

    def nest(items):  # items: (weight, dict), weights summing to 1
        if len(items) == 1:
            return items[0][1]
        rest = sum(w for w, _ in items[1:])
        return {"type": "blendbsdf", "weight": rest, "bsdf_0": items[0][1],
                "bsdf_1": nest([(w / rest, d) for w, d in items[1:]])}

    return nest(list(zip(c, dicts)))


def to_mitsuba(model, params, *, approximate: bool = False) -> dict:
    """The Mitsuba 3 BSDF of ``model`` at ``params``, as a ``mitsuba.load_dict`` dict.

    ``model``: a registered name (``"rough_conductor+lambert"``) or a ``Model`` record;
    ``params``: its ``Params``. Raises :class:`ExportError` for a model Mitsuba does not have
    (the message lists the exportable ones), parameters it cannot hold, or, unless
    ``approximate=True``, a setting listed by :func:`differences`. Plain Python values only
    (JSON-serialisable); angles in Mitsuba's units (hair tilt in degrees).
    """
    _, leaves = _checked(model, params)
    diffs = differences(model, params)
    if diffs and not approximate:
        raise ExportError("no exact Mitsuba equivalent: " + "; ".join(diffs) + ". Pass approximate=True "
                          "(appearance-jax export --approximate) to export anyway, or refit with "
                          "--param shadowing=separable (rough_plastic: also tables=mitsuba)")
    if len(leaves) == 1:
        return _leaf_dict(*leaves[0])
    return _blend(leaves)


# ---------------------------------------------------------------------------------------
# XML

def _num(v: float) -> str:
    return repr(float(v))


def _xml_lines(d: dict, indent: str, attrs: str) -> list[str]:
    lines = [f"{indent}<bsdf type={quoteattr(d['type'])}{attrs}>"]
    inner = indent + "    "
    for key, v in d.items():
        if key == "type":
            continue
        name = quoteattr(key)
        if isinstance(v, bool):
            lines.append(f"{inner}<boolean name={name} value=\"{'true' if v else 'false'}\"/>")
        elif isinstance(v, int):
            lines.append(f"{inner}<integer name={name} value=\"{v}\"/>")
        elif isinstance(v, float):
            lines.append(f"{inner}<float name={name} value=\"{_num(v)}\"/>")
        elif isinstance(v, str):
            lines.append(f"{inner}<string name={name} value={quoteattr(v)}/>")
        elif isinstance(v, dict) and v.get("type") == "rgb":
            lines.append(f"{inner}<rgb name={name} value=\"{', '.join(_num(x) for x in v['value'])}\"/>")
        elif isinstance(v, dict):
            lines += _xml_lines(v, inner, "")
        else:
            raise TypeError(f"cannot write {key} = {v!r} as Mitsuba XML")
    lines.append(f"{indent}</bsdf>")
    return lines


def dict_to_xml(d: dict, *, id: str = "material", comment: str | None = None) -> str:
    """A :func:`to_mitsuba` dict as a standalone Mitsuba 3 XML document: one ``<bsdf>`` element
    (``version="3.0.0"``, id ``id``) that ``mitsuba.load_file`` loads as the BSDF and that can be
    pasted into a scene and referenced with ``<ref id="..."/>``."""
    if not isinstance(id, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", id):
        raise ExportError(f"id = {id!r}: give a name of letters, digits, '_', '.', '-' (not starting with a digit)")
    head = ['<?xml version="1.0" encoding="utf-8"?>']
    if comment:
        head.append("<!-- " + escape(comment).replace("--", "- -") + " -->")
    return "\n".join(head + _xml_lines(d, "", f" id={quoteattr(id)} version=\"3.0.0\"")) + "\n"


def to_mitsuba_xml(model, params, *, approximate: bool = False, id: str = "material") -> str:
    """:func:`to_mitsuba` written as Mitsuba 3 XML (see :func:`dict_to_xml`)."""
    return dict_to_xml(to_mitsuba(model, params, approximate=approximate), id=id)


# ---------------------------------------------------------------------------------------
# params.json

def read_params_json(path) -> dict:
    """The record a fit wrote (``appearance-jax fit --out DIR`` -> ``DIR/params.json``), checked to
    be a regular, small, UTF-8 JSON file holding an object with a ``model`` name."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ExportError(f"params.json {path!r}: no such file")
    if os.path.isdir(path):
        raise ExportError(f"params.json {path!r} is a directory; give the params.json file a fit wrote "
                          "(appearance-jax fit --out DIR writes DIR/params.json)")
    try:
        data = read_regular_file(path, MAX_RECORD_BYTES)  # no FIFO, device or huge file
        rec = json.loads(data.decode("utf-8"))
    except FileProblem as e:
        raise ExportError(f"params.json {path!r}: {e.problem}") from None
    except UnicodeDecodeError as e:
        raise ExportError(f"params.json {path!r} is not UTF-8 text: {e}") from None
    except json.JSONDecodeError as e:
        raise ExportError(f"params.json {path!r} is not JSON: {e}") from None
    if not isinstance(rec, dict) or not isinstance(rec.get("model"), str):
        raise ExportError(f"params.json {path!r} holds no fit record (a JSON object with a 'model' name)")
    return rec


def _values_from_labels(rec: dict, path: str) -> dict:
    """Field values from the fitted labels ("alpha", "eta[R]", ...), the fixed and static records."""
    values = dict(rec.get("static") or {})
    values.update(rec.get("fixed") or {})
    grouped: dict[str, list] = {}
    for label, entry in (rec.get("parameters") or {}).items():
        m = re.fullmatch(r"([A-Za-z_]\w*)(\[.*\])?", label)
        v = entry.get("value") if isinstance(entry, dict) else None
        if m is None or not isinstance(v, (int, float)):
            raise ExportError(f"params.json {path!r}: parameters[{label!r}] is not a fitted value record")
        grouped.setdefault(m.group(1), []).append((m.group(2) is not None, float(v)))
    for name, vals in grouped.items():
        values[name] = vals[0][1] if not vals[0][0] else tuple(v for _, v in vals)
    return values


def from_params_json(path) -> tuple[Model, object]:
    """(model, Params) rebuilt from a fit's ``params.json``.

    Uses the record's ``params`` (every field, static ones included, as the fit ended) when
    present, else the fitted ``parameters`` (labels ``alpha``, ``eta[R]``, ...) over the
    ``fixed`` and ``static`` records and the model's defaults. Raises :class:`ExportError`
    naming the file for a missing, non-JSON or foreign file, an unknown model or values the
    model's ``Params`` rejects.
    """
    path = os.fspath(path)
    rec = read_params_json(path)
    model = _resolve(rec["model"])
    values = rec.get("params")
    if not isinstance(values, dict):
        values = _values_from_labels(rec, path)
    fields = set(param_specs(model.Params))
    unknown = sorted(set(values) - fields)
    if unknown:
        raise ExportError(f"params.json {path!r}: {', '.join(unknown)} not fields of {model.name}.Params "
                          f"({', '.join(sorted(fields))})")
    try:
        params = model.Params(**values)
    except (TypeError, ValueError) as e:
        raise ExportError(f"params.json {path!r}: {e}") from None
    return model, params
