"""Loader for refractiveindex.info database files (YAML) -> refractive-index pytrees.

A database file (https://refractiveindex.info, CC0; format of the
polyanskiy/refractiveindex.info-database repository) has a ``DATA`` list whose entries are

- ``type: tabulated nk`` / ``tabulated n`` / ``tabulated k`` with a ``data`` block of rows
  "wavelength value(s)" (wavelength in micrometres);
- ``type: formula N`` (N = 1..9) with ``coefficients`` and ``wavelength_range`` (um).

One entry gives n (and possibly k); a second may add k (a formula for n plus a
``tabulated k`` is common). The result is a :class:`~appearance_jax.optics.refractive_index.Tabulated`,
:class:`~appearance_jax.optics.refractive_index.Formula` or, for two sources,
:class:`~appearance_jax.optics.refractive_index.Combined` model, taking wavelengths in **nm**
and valid on the stated wavelength range (the intersection when n and k come from different
entries). Formulas are documented in :mod:`appearance_jax.optics.refractive_index`.

Malformed or unsupported files raise ``ValueError`` naming the file and the problem.

The YAML is read defensively (a data file is data, never code): ``yaml.safe_load`` (no Python
objects are ever constructed), and before it the document is checked event by event: YAML
anchors and aliases (``&a``, ``*a``, ``<<: *a``) are refused, since nested aliases expand
exponentially ("billion laughs": 8 lines that stand for 10^8 strings; the database files never
use them), nesting deeper than :data:`MAX_YAML_DEPTH` levels is refused (the files nest 3 or 4
deep), and so is a text longer than :data:`MAX_YAML_BYTES` (the largest database files are a few
hundred kB). A file must be a regular file (a FIFO or device is refused before it is opened),
in UTF-8.

Example::

    from appearance_jax.optics.refractiveindex_yaml import load_material
    gold = load_material("Au_Johnson")
    n, k = gold(550.0)            # about 0.424, 2.472 (interpolated between table rows)
    eta = gold.complex([650.0, 510.0, 475.0])
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import yaml

from ..core.files import FileProblem, read_regular_file
from .refractive_index import (
    FORMULA_NAMES,
    Combined,
    Formula,
    Tabulated,
    formula_coefficient_count_error,
)

_UM_TO_NM = 1000.0
MAX_YAML_BYTES = 16 * 2**20  # refused above this size (text length in characters for a string)
MAX_YAML_DEPTH = 32  # refused above this nesting of lists and mappings


def _fail(source: str, msg: str):
    raise ValueError(f"refractiveindex.info file {source}: {msg}")


def _parse_numbers(source: str, what: str, text) -> np.ndarray:
    """Whitespace-separated numbers (a YAML scalar or list) -> float array."""
    if isinstance(text, (int, float)):
        return np.array([float(text)])
    if isinstance(text, (list, tuple)):
        tokens = [str(t) for t in text]
    elif isinstance(text, str):
        tokens = text.split()
    else:
        _fail(source, f"{what} must be numbers, got {type(text).__name__}")
    try:
        return np.array([float(t) for t in tokens], dtype=float)
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        _fail(source, f"{what} contains the non-numeric value {bad!r}")


def _is_float(t) -> bool:
    try:
        float(t)
        return True
    except ValueError:
        return False


def _parse_table(source: str, entry_no: int, kind: str, data, ncols: int) -> np.ndarray:
    """The ``data`` block of a tabulated entry -> (rows, ncols) array, wavelengths in um."""
    if not isinstance(data, str):
        _fail(source, f"DATA entry {entry_no} ({kind}) has no 'data' block of rows")
    rows = []
    for line_no, line in enumerate(data.splitlines(), start=1):
        if not line.strip():
            continue
        tokens = line.split()
        if len(tokens) != ncols:
            _fail(source, f"DATA entry {entry_no} ({kind}), row {line_no} {line.strip()!r}: expected "
                          f"{ncols} numbers, got {len(tokens)}")
        try:
            rows.append([float(t) for t in tokens])
        except ValueError:
            _fail(source, f"DATA entry {entry_no} ({kind}), row {line_no} {line.strip()!r} is not numeric")
    if not rows:
        _fail(source, f"DATA entry {entry_no} ({kind}) has an empty table")
    table = np.array(rows, dtype=float)
    if not np.all(np.isfinite(table)):
        _fail(source, f"DATA entry {entry_no} ({kind}) contains non-finite values")
    if np.any(table[:, 0] <= 0):
        _fail(source, f"DATA entry {entry_no} ({kind}) has a non-positive wavelength")
    # The database has a few imperfect tables (Querry's hematite: a repeated row, and a
    # row 3.6911 um between 3.8760 and 3.9063 um). Repeated identical rows are dropped;
    # rows out of order are sorted, with a warning; one wavelength with two different
    # values is an error.
    if np.any(np.diff(table[:, 0]) <= 0):
        if np.any(np.diff(table[:, 0]) < 0):
            warnings.warn(f"refractiveindex.info file {source}: DATA entry {entry_no} ({kind}) has rows out "
                          "of wavelength order; they were sorted", stacklevel=4)
        table = np.unique(table, axis=0)  # sorts by wavelength, drops identical rows
        wl = table[:, 0]
        if np.any(np.diff(wl) == 0):
            i = int(np.argmax(np.diff(wl) == 0))
            _fail(source, f"DATA entry {entry_no} ({kind}) gives two different values at {wl[i]:g} um")
    return table


def _parse_formula(source: str, entry_no: int, kind: str, entry: dict, name: str) -> Formula:
    try:
        number = int(kind.split()[1])
    except (IndexError, ValueError):
        _fail(source, f"DATA entry {entry_no} has the unsupported type {kind!r}")
    if number not in FORMULA_NAMES:
        _fail(source, f"DATA entry {entry_no} has the unsupported type {kind!r} (known: formula 1-9, "
                      "tabulated n, tabulated k, tabulated nk)")
    if "coefficients" not in entry:
        _fail(source, f"DATA entry {entry_no} ({kind}) has no 'coefficients'")
    coeffs = _parse_numbers(source, f"the coefficients of DATA entry {entry_no} ({kind})", entry["coefficients"])
    if not np.all(np.isfinite(coeffs)):
        _fail(source, f"DATA entry {entry_no} ({kind}) has non-finite coefficients")
    err = formula_coefficient_count_error(number, coeffs.size)
    if err is not None:
        _fail(source, f"DATA entry {entry_no} ({kind}, {FORMULA_NAMES[number]}) has {coeffs.size} "
                      f"coefficients; expected {err}")
    # Older database versions call the key 'range'.
    rng = entry.get("wavelength_range", entry.get("range"))
    if rng is None:
        _fail(source, f"DATA entry {entry_no} ({kind}) has no 'wavelength_range'")
    r = _parse_numbers(source, f"the wavelength_range of DATA entry {entry_no}", rng)
    if r.size != 2 or not (0 < r[0] < r[1]) or not np.all(np.isfinite(r)):
        _fail(source, f"DATA entry {entry_no} ({kind}) has an invalid wavelength_range {rng!r} "
                      "(expected 'min max' in um, 0 < min < max)")
    return Formula(kind=number, coefficients=coeffs,
                   wavelength_range_nm=(float(r[0]) * _UM_TO_NM, float(r[1]) * _UM_TO_NM), name=name)


def _check_events(text: str, source: str) -> None:
    """Refuse anchors, aliases and deep nesting, from the parser's events (nothing is built)."""
    depth = 0
    for ev in yaml.parse(text, Loader=yaml.SafeLoader):
        where = f"line {ev.start_mark.line + 1}"
        if isinstance(ev, yaml.AliasEvent) or getattr(ev, "anchor", None) is not None:
            _fail(source, f"uses a YAML anchor or alias ({where}); they are not accepted in data files "
                          "(nested aliases expand exponentially): write the values out")
        if isinstance(ev, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            depth += 1
            if depth > MAX_YAML_DEPTH:
                _fail(source, f"nests lists/mappings more than {MAX_YAML_DEPTH} levels deep ({where}); "
                              "a refractiveindex.info file nests 3 or 4 levels")
        elif isinstance(ev, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            depth -= 1


def parse_refractiveindex_yaml(text: str, source: str = "<string>", name: str | None = None):
    """Parse the YAML text of a refractiveindex.info file; ``source`` names it in errors.

    Raises:
        ValueError: ``refractiveindex.info file {source}: ...``: not YAML, anchors or aliases,
            nesting deeper than :data:`MAX_YAML_DEPTH`, longer than :data:`MAX_YAML_BYTES`
            characters, or not a valid database file.
    """
    if not isinstance(text, str):
        _fail(source, f"text must be a str, got {type(text).__name__}")
    if len(text) > MAX_YAML_BYTES:
        _fail(source, f"has {len(text)} characters, more than the limit of {MAX_YAML_BYTES}")
    try:
        _check_events(text, source)
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        _fail(source, f"is not valid YAML ({e})")
    if not isinstance(doc, dict) or "DATA" not in doc:
        _fail(source, "has no DATA section (not a refractiveindex.info data file)")
    entries = doc["DATA"]
    if not isinstance(entries, list) or not entries:
        _fail(source, "DATA must be a non-empty list of entries")
    name = name if name is not None else Path(source).stem

    n_src, k_src = None, None  # (model, entry number)
    for i, entry in enumerate(entries, start=1):
        if not isinstance(entry, dict) or "type" not in entry:
            _fail(source, f"DATA entry {i} has no 'type'")
        kind = " ".join(str(entry["type"]).split())
        if kind.startswith("formula"):
            model = _parse_formula(source, i, kind, entry, name)
        elif kind in ("tabulated nk", "tabulated n", "tabulated k"):
            t = _parse_table(source, i, kind, entry.get("data"), 3 if kind == "tabulated nk" else 2)
            wl_nm = t[:, 0] * _UM_TO_NM
            if kind == "tabulated nk":
                n, k = t[:, 1], t[:, 2]
            elif kind == "tabulated n":
                n, k = t[:, 1], None
            else:
                # k only: n is a placeholder that is never read (Combined takes n elsewhere)
                n, k = np.zeros_like(t[:, 1]), t[:, 1]
            if np.any(n < 0):
                _fail(source, f"DATA entry {i} ({kind}) has a negative n")
            # Negative k is kept as given (Querry's hematite has k < 0 beyond 47 um).
            model = Tabulated(wavelength_nm=wl_nm, n=n, k=k, name=name)
        else:
            _fail(source, f"DATA entry {i} has the unsupported type {kind!r} (known: formula 1-9, "
                          "tabulated n, tabulated k, tabulated nk)")
        if kind != "tabulated k":
            if n_src is not None:
                _fail(source, f"DATA entries {n_src[1]} and {i} both give n")
            n_src = (model, i)
        if kind in ("tabulated k", "tabulated nk"):
            if k_src is not None:
                _fail(source, f"DATA entries {k_src[1]} and {i} both give k")
            k_src = (model, i)
    if n_src is None:
        _fail(source, "has no entry giving the refractive index n (only 'tabulated k')")

    n_model = n_src[0]
    if k_src is None or k_src[0] is n_model:
        return n_model
    combined = Combined(n_model=n_model, k_model=k_src[0], name=name)
    lo, hi = combined._range_nm()
    if lo > hi:
        _fail(source, f"the n data ({n_model._range_nm()} nm) and the k data "
                      f"({k_src[0]._range_nm()} nm) do not overlap")
    return combined


def load_refractiveindex_yaml(path, name: str | None = None):
    """Load a refractiveindex.info database file (path to a ``.yml``) as a refractive-index model.

    Returns a model callable on wavelengths in nm -> ``(n, k)``; ``name`` (default: the
    file stem) is used in its error messages.

    Raises:
        ValueError: ``refractiveindex.info file {path}: ...``: missing or unreadable, not a regular
            file (checked before opening, so a FIFO cannot block), larger than
            :data:`MAX_YAML_BYTES`, not UTF-8, or malformed (:func:`parse_refractiveindex_yaml`).
    """
    on_disk = isinstance(path, (str, os.PathLike))
    source = os.fspath(path) if on_disk else str(path)
    try:
        # a shipped resource that is not a file on disk (e.g. in a zip) is read through its own API
        data = read_regular_file(source, MAX_YAML_BYTES) if on_disk else path.read_bytes()
    except FileProblem as e:
        _fail(source, e.problem)
    except OSError as e:
        raise ValueError(f"refractiveindex.info file {source}: cannot be read ({e})") from e
    if len(data) > MAX_YAML_BYTES:
        _fail(source, f"file has {len(data)} bytes, more than the limit of {MAX_YAML_BYTES} bytes")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        _fail(source, f"is not UTF-8 text (byte 0x{data[e.start]:02x} on line {line}); save it as UTF-8")
    return parse_refractiveindex_yaml(text, source=source, name=name)


def available_materials() -> list[str]:
    """Names of the shipped refractiveindex.info data files (see data/refractive_index/PROVENANCE.md)."""
    from ..data import path as data_path

    folder = data_path("refractive_index")
    names = []
    for entry in folder.iterdir():
        if entry.name.endswith(".yml") and not entry.name.endswith("_about.yml"):
            names.append(entry.name[: -len(".yml")])
    return sorted(names)


def load_material(name: str):
    """Load a shipped material by name, e.g. ``load_material("Au_Johnson")``."""
    from ..data import path as data_path

    names = available_materials()
    if name not in names:
        raise ValueError(f"unknown material {name!r}; available: {', '.join(names)}")
    return load_refractiveindex_yaml(data_path("refractive_index", name + ".yml"), name=name)


__all__ = ["load_refractiveindex_yaml", "parse_refractiveindex_yaml", "load_material", "available_materials",
           "MAX_YAML_BYTES", "MAX_YAML_DEPTH"]
