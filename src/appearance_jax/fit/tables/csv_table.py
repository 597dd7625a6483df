"""CSV tables of gonioreflectometer measurements: the ``appearance-jax table v1`` schema
(full schema: docs/tables.md).

:func:`read_csv` turns a file in this schema into a :class:`~appearance_jax.fit.tables.table.Table`,
:func:`write_csv` writes one back. Every malformed file raises :class:`TableError` with a
message ``{path}:{line}: {problem}`` (line = 1-based physical line of the file, as an editor
shows it), so the offending cell can be found directly.

In short: ``#`` header lines (``# appearance-jax table v1``; the required
``# quantity: brdf | cosine_weighted_brdf | reflectance_factor``, i.e. f in 1/sr,
f |cos theta_o| or R = pi f / rho_w; ``# white_reference: rho_w``, default 0.99, with
``reflectance_factor`` only; any other ``#`` line is a comment), then one column line and
comma-separated rows. Columns, in any order: the angles in **degrees**, ``theta_i, phi_i,
theta_o, phi_o`` (full geometry) or ``theta_i, theta_o`` with theta_o **signed** (in-plane:
> 0 forward/mirror side, < 0 retro side, Padrón 2025 Fig. 4.4); the values in the unit of the
quantity, ``R, G, B`` (linear RGB) or one column per wavelength in nm named by the number;
optional ``sigma_<band>`` (one standard deviation) for every value column or none. Numbers are
plain decimal text (``1_0``, ``30deg`` are errors). An empty value cell or ``nan``/``NA`` is a
missing sample and a negative value is not a BRDF value: both masked, never zero, and counted
by reason in ``Table.masked`` (docs/tables.md lists which bad values are errors and which are
masked). Duplicate geometries are an error. Lines may end in LF, CRLF or CR alone; the file
must be a regular file (size limit :data:`MAX_CSV_BYTES`, checked before reading) in UTF-8.
Reading gives angles in radians; an in-plane file becomes :meth:`Table.in_plane`.

Example (a reflectance-factor table measured in the full geometry)::

    # appearance-jax table v1
    # quantity: reflectance_factor
    # white_reference: 0.99
    # instrument: in-house gonioreflectometer, 5 degree steps
    # sample: red velvet, pile along +x
    theta_i,phi_i,theta_o,phi_o,R,G,B,sigma_R,sigma_G,sigma_B
    30,0,30,180,0.12,0.10,0.08,0.002,0.002,0.002
    30,0,45,180,0.09,0.07,0.05,0.002,0.002,0.002
    30,0,60,180,,0.05,0.04,,0.002,0.002
    30,0,45,90,0.15,0.12,0.09,0.003,0.003,0.003

The same sample in-plane (-30 is retro-reflection for theta_i = 30), spectral, BRDF in 1/sr::

    # appearance-jax table v1
    # quantity: brdf
    theta_i,theta_o,450,550,650
    30,-30,0.041,0.035,0.060
    30,0,0.032,0.030,0.051
    30,30,0.094,0.088,0.120

(both examples are read by tests/fit/tables/test_csv_table.py.)
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

from ...core.files import FileProblem, read_regular_file
from .csv_cells import (
    EMPTY_ROW_REASON,
    FULL_ANGLES,
    IN_PLANE_ANGLES,
    MISSING_REASON,
    NEGATIVE_REASON,
    RGB,
    SCHEMA_LINE,
    TableError,
    angle_cell,
    err_at,
    is_wavelength,
    number_cell,
    parse_number,
)
from .csv_write import write_csv
from .table import QUANTITIES, Table

__all__ = ["TableError", "read_csv", "write_csv", "SCHEMA_LINE", "MAX_CSV_BYTES"]

MAX_CSV_BYTES = 64 * 2**20  # default size limit of read_csv: 64 MiB, about 600 000 rows of 10 columns
_DUP_DECIMALS = 9  # duplicate rows: angles compared after rounding to 1e-9 degree
_LINE_END = re.compile(r"\r\n|\r|\n")  # as editors count lines: LF, CRLF, or CR alone (old Mac files)

_UNIT_NAME = re.compile(r"([0-9]+(?:\.[0-9]*)?)\s*(?:nm|um|µm)\Z", re.IGNORECASE)  # '550nm', '550 nm'
_EXPECTED_COLUMNS = ("expected theta_i, phi_i, theta_o, phi_o, value columns R,G,B or "
                     "wavelengths in nm, optional sigma_<band>")


# ---------------------------------------------------------------------------- reading
def read_csv(path, *, max_bytes: int | None = None) -> Table:
    """Read a table in the ``appearance-jax table v1`` CSV schema (docs/tables.md).

    Args:
        path: file name (str or path-like); it is also the ``source`` of the table and the
            prefix of every error message.
        max_bytes: refuse larger files, from their size, before reading them (default
            :data:`MAX_CSV_BYTES`, 64 MiB; pass a larger number to read a larger table).

    Returns:
        :class:`Table` with angles in radians and values in the file's quantity. Missing and
        negative values are masked and counted in ``Table.masked`` (docs/tables.md, "Cells").

    Raises:
        TableError: for any malformed input, with ``{path}:{line}:`` and the problem, or
            ``{path}:`` for a problem of the whole file (not a regular file, too large).
        OSError: the file does not exist or cannot be read (FileNotFoundError, ...).
    """
    p = os.fspath(path)
    lines = _read_lines(p, MAX_CSV_BYTES if max_bytes is None else max_bytes)
    if not any(ln.strip() for ln in lines):
        raise err_at(p, 1, "empty file (expected '# quantity: ...', a column header line and data rows)")

    meta: dict[str, tuple[str, int]] = {}
    header_no = None
    header: list[str] = []
    rows: list[tuple[int, list[str]]] = []
    for no, raw in enumerate(lines, start=1):
        s = raw.strip()
        if not s:
            continue
        if s.startswith("#"):
            _parse_comment(p, no, s, meta, header_no)
            continue
        cells = [c.strip() for c in s.split(",")]
        if header_no is None:
            header_no, header = no, cells
        else:
            rows.append((no, cells))

    if "quantity" not in meta:
        raise err_at(p, 1, "missing header line '# quantity: ...' (one of " + ", ".join(QUANTITIES) + ")")
    quantity = meta["quantity"][0]
    white = 0.99
    if "white_reference" in meta:
        w_text, w_no = meta["white_reference"]
        if quantity != "reflectance_factor":
            raise err_at(p, w_no, f"white_reference given for quantity {quantity}; it is only meaningful "
                                "for quantity reflectance_factor")
        white = parse_number(w_text)
        if white is None:
            raise err_at(p, w_no, f"white_reference = {w_text!r} is not a number")
        if not (0.0 < white <= 1.0):  # also rejects nan
            raise err_at(p, w_no, f"white_reference = {w_text} is outside (0, 1] "
                                "(a reflectance, e.g. 0.99 for Spectralon, not a percentage)")
    if header_no is None:
        raise err_at(p, len(lines), "no column header line (" + _EXPECTED_COLUMNS + ")")

    cols = _parse_header(p, header_no, header)
    if not rows:
        raise err_at(p, header_no, "no data rows after the column header")

    n_cols = len(header)
    angle_names = cols["angles"]
    value_idx, sigma_idx, bands = cols["value_idx"], cols["sigma_idx"], cols["bands"]
    n, b = len(rows), len(bands)
    angles = np.empty((n, len(angle_names)))
    values = np.full((n, b), np.nan)
    sigma = np.full((n, b), np.nan) if sigma_idx is not None else None
    mask = np.zeros((n, b), dtype=bool)
    negative = np.zeros((n, b), dtype=bool)
    seen: dict[tuple, int] = {}
    for r, (no, cells) in enumerate(rows):
        if len(cells) != n_cols:
            raise err_at(p, no, f"row has {len(cells)} cells, expected {n_cols} "
                              f"(one per column of the header on line {header_no})")
        for a, name in enumerate(angle_names):
            angles[r, a] = angle_cell(p, no, name, cells[cols["angle_idx"][a]], in_plane=cols["in_plane"])
        for k in range(b):
            name, text = header[value_idx[k]], cells[value_idx[k]]
            v = number_cell(p, no, name, text, allow_missing=True)
            if v is not None and v < 0:  # not a BRDF value: masked and counted (docs/tables.md)
                negative[r, k] = True
            elif v is not None:
                values[r, k], mask[r, k] = v, True
            if sigma is not None:
                s_name, s_text = header[sigma_idx[k]], cells[sigma_idx[k]]
                # a missing sample has no uncertainty: its sigma cell may be empty as well
                s = number_cell(p, no, s_name, s_text, allow_missing=v is None)
                if s is not None:
                    if s < 0:
                        raise err_at(p, no, f"{s_name} = {s_text} is negative (a standard deviation is >= 0)")
                    if mask[r, k]:
                        sigma[r, k] = s
        key = _geometry_key(angles[r], angle_names)
        if key in seen:
            raise err_at(p, no, f"duplicate of line {seen[key]} (same {', '.join(angle_names)})")
        seen[key] = no

    if not mask.any():
        raise err_at(p, header_no, f"no valid value in the {n} data rows (every value cell is missing "
                                   "or negative)")
    common = dict(mask=mask, sigma=sigma, quantity=quantity, bands=tuple(bands),
                  wavelengths=cols["wavelengths"], white_reference=white, source=p,
                  masked=_masked_counts(mask, negative))
    rad = np.deg2rad(angles)
    if cols["in_plane"]:
        return Table.in_plane(rad[:, 0], rad[:, 1], values, **common)
    two_pi = 2 * np.pi
    return Table(theta_i=rad[:, 0], phi_i=np.mod(rad[:, 1], two_pi), theta_o=rad[:, 2],
                 phi_o=np.mod(rad[:, 3], two_pi), values=values, **common)


def _read_lines(p: str, max_bytes: int) -> list[str]:
    """The file's lines, checked: a regular file of at most ``max_bytes``, UTF-8 text, no NUL."""
    try:
        data = read_regular_file(p, max_bytes)
    except FileProblem as e:
        hint = " (read_csv(path, max_bytes=...) reads larger tables)" if "limit" in e.problem else ""
        raise TableError(f"{p}: {e.problem}{hint}") from None
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise err_at(p, 1, "UTF-16 text (a byte-order mark 0x" + data[:2].hex() + "); save the table as UTF-8")
    if data.startswith(b"\xef\xbb\xbf"):  # the UTF-8 byte-order mark spreadsheets like to prepend
        data = data[3:]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = len(_LINE_END.split(data[:e.start].decode("utf-8", "replace")))
        raise err_at(p, line, f"not UTF-8 text (byte 0x{data[e.start]:02x}); save the table as UTF-8") from None
    nul = text.find("\0")
    if nul >= 0:
        raise err_at(p, len(_LINE_END.split(text[:nul])), "NUL character: a binary file, not CSV text")
    # physical lines as an editor numbers them: LF, CRLF or CR alone end a line
    lines = _LINE_END.split(text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def _masked_counts(mask, negative) -> dict:
    """``Table.masked`` of a read table: band entries per reason, reasons with 0 left out."""
    missing = ~mask & ~negative
    whole = missing.all(axis=1)
    counts = {MISSING_REASON: int(missing[~whole].sum()), EMPTY_ROW_REASON: int(missing[whole].sum()),
              NEGATIVE_REASON: int(negative.sum())}
    return {why: n for why, n in counts.items() if n}


_KEY_RE = re.compile(r"^#\s*([A-Za-z_][\w-]*)\s*:\s*(.*?)\s*$")
_SCHEMA_RE = re.compile(r"^#\s*appearance-jax\s+table\s+v(\S*)\s*$", re.IGNORECASE)


def _parse_comment(p, no, s, meta, header_no):
    """Record '# quantity:' / '# white_reference:' lines; everything else is a free comment."""
    m = _SCHEMA_RE.match(s)
    if m:
        if m.group(1) != "1":
            raise err_at(p, no, f"unsupported schema version 'v{m.group(1)}' (this reader knows "
                              "'appearance-jax table v1')")
        return
    m = _KEY_RE.match(s)
    if not m or m.group(1).lower() not in ("quantity", "white_reference"):
        return
    key, value = m.group(1).lower(), m.group(2)
    if key == "quantity":
        value = value.lower()
    if header_no is not None:
        # after the column line it would be ambiguous which rows it applies to
        raise err_at(p, no, f"'# {key}: ...' must come before the column header (line {header_no})")
    if key in meta:
        raise err_at(p, no, f"second '# {key}:' line (first on line {meta[key][1]})")
    if key == "quantity" and value not in QUANTITIES:
        raise err_at(p, no, f"unknown quantity {value!r} (one of {', '.join(QUANTITIES)})")
    meta[key] = (value, no)


def _parse_header(p, no, header):
    """Classify the column names: geometry, value columns (RGB or wavelengths), sigma columns."""
    if len(header) == 1 and ";" in header[0]:
        raise err_at(p, no, "columns must be separated by commas, found ';' (re-export the CSV with ',')")
    if all(is_wavelength(name) for name in header) and len(header) >= 3:
        # a first data row where the column names should be: say so, not 'duplicate column 30'
        raise err_at(p, no, f"no column header line: this line looks like data ({_EXPECTED_COLUMNS})")
    index: dict[str, int] = {}
    for c, name in enumerate(header):
        if name == "":
            raise err_at(p, no, f"empty column name (column {c + 1})")
        if name in index:
            raise err_at(p, no, f"column '{name}' appears twice (columns {index[name] + 1} and {c + 1})")
        index[name] = c
    angle_cols, rgb, spectral, sigmas = [], [], [], []
    for name in header:
        if name in FULL_ANGLES:
            angle_cols.append(name)
        elif name in RGB:
            rgb.append(name)
        elif name.startswith("sigma_"):
            sigmas.append(name)
        elif is_wavelength(name):
            spectral.append(name)
        else:
            unit = _UNIT_NAME.match(name)
            hint = (f"; a wavelength column is named by its number in nm alone, e.g. '{unit.group(1)}'"
                    if unit else "")
            raise err_at(p, no, f"unknown column '{name}' ({_EXPECTED_COLUMNS}{hint})")

    # geometry: any azimuth column means the full geometry, otherwise in-plane
    in_plane = not ({"phi_i", "phi_o"} & set(angle_cols))
    need = IN_PLANE_ANGLES if in_plane else FULL_ANGLES
    missing = [a for a in need if a not in index]
    if missing:
        raise err_at(p, no, f"missing column{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                          "(full geometry needs theta_i, phi_i, theta_o, phi_o; in-plane needs "
                          "theta_i, theta_o)")

    if rgb and spectral:
        raise err_at(p, no, f"mixes RGB columns ({', '.join(rgb)}) and spectral columns "
                          f"({', '.join(spectral)}); use one or the other")
    if not rgb and not spectral:
        raise err_at(p, no, "no value columns (R,G,B or one column per wavelength in nm)")
    wavelengths = None
    if rgb:
        absent = [c for c in RGB if c not in rgb]
        if absent:
            raise err_at(p, no, f"RGB table without column{'s' if len(absent) > 1 else ''} "
                              f"{', '.join(absent)} (R, G and B are all required)")
        bands = list(RGB)
    else:
        bands = spectral
        wl = []
        for name in spectral:
            w = parse_number(name)
            if not math.isfinite(w) or w <= 0:
                raise err_at(p, no, f"wavelength column '{name}' is not a positive number of nm")
            if wl and w <= wl[-1]:
                raise err_at(p, no, f"wavelength columns must be strictly increasing: '{name}' "
                                  f"after '{spectral[len(wl) - 1]}'")
            wl.append(w)
        wavelengths = np.array(wl)

    sigma_idx = None
    if sigmas:
        by_band = {}
        for s in sigmas:
            band = _sigma_band(s[len("sigma_"):], bands, wavelengths)
            if band is None:
                raise err_at(p, no, f"sigma column '{s}' without its value column '{s[len('sigma_'):]}'")
            if band in by_band:
                raise err_at(p, no, f"columns '{by_band[band]}' and '{s}' are both the sigma of band {band}")
            by_band[band] = s
        absent = ["sigma_" + bnd for bnd in bands if bnd not in by_band]
        if absent:
            raise err_at(p, no, f"missing sigma column{'s' if len(absent) > 1 else ''} {', '.join(absent)} "
                              "(give sigma_<band> for every value column or for none)")
        sigma_idx = [index[by_band[bnd]] for bnd in bands]

    return dict(in_plane=in_plane, angles=need, angle_idx=[index[a] for a in need],
                value_idx=[index[bnd] for bnd in bands], sigma_idx=sigma_idx, bands=bands,
                wavelengths=wavelengths)


def _sigma_band(suffix, bands, wavelengths):
    """The band a ``sigma_<suffix>`` column belongs to (wavelengths compared as numbers)."""
    if suffix in bands:
        return suffix
    if wavelengths is not None and is_wavelength(suffix):
        hit = np.flatnonzero(wavelengths == parse_number(suffix))
        if hit.size:
            return bands[int(hit[0])]
    return None


def _geometry_key(row_deg, names):
    # round first, then reduce modulo 360, so that 359.9999999999 and 0 coincide
    key = []
    for v, name in zip(row_deg, names):
        r = round(float(v), _DUP_DECIMALS)
        if name.startswith("phi"):
            r = math.fmod(r, 360.0)
        key.append(r + 0.0)  # + 0.0: -0.0 -> 0.0
    return tuple(key)
