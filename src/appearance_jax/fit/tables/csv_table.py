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
optional ``sigma_<band>`` (one standard deviation) for every value column or none. An empty
value cell or ``nan``/``NA`` is a missing sample: masked, never zero. Duplicate geometries are
an error. Reading gives angles in radians; an in-plane file becomes :meth:`Table.in_plane`.

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

from .table import QUANTITIES, Table

__all__ = ["TableError", "read_csv", "write_csv", "SCHEMA_LINE"]

SCHEMA_LINE = "# appearance-jax table v1"
FULL_ANGLES = ("theta_i", "phi_i", "theta_o", "phi_o")
IN_PLANE_ANGLES = ("theta_i", "theta_o")
RGB = ("R", "G", "B")
MISSING_TOKENS = ("", "nan", "na")  # compared lower-case
MISSING_REASON = "missing value"
_DUP_DECIMALS = 9  # duplicate rows: angles compared after rounding to 1e-9 degree

_EXPECTED_COLUMNS = ("expected theta_i, phi_i, theta_o, phi_o, value columns R,G,B or "
                     "wavelengths in nm, optional sigma_<band>")


class TableError(ValueError):
    """A malformed measurement file; the message starts with ``{path}:{line}: `` (text files)
    or ``{path}: `` (binary files such as MERL ``.binary``, which have no lines)."""


def _err(path, line, msg) -> TableError:
    return TableError(f"{path}:{line}: {msg}")


def _is_wavelength(name: str) -> bool:
    try:
        float(name)
    except ValueError:
        return False
    return True


# ---------------------------------------------------------------------------- reading
def read_csv(path) -> Table:
    """Read a table in the ``appearance-jax table v1`` CSV schema (docs/tables.md).

    Args:
        path: file name (str or path-like); it is also the ``source`` of the table and the
            prefix of every error message.

    Returns:
        :class:`Table` with angles in radians and values in the file's quantity.

    Raises:
        TableError: for any malformed input, with ``{path}:{line}:`` and the problem.
    """
    p = os.fspath(path)
    with open(p, "rb") as f:
        data = f.read()
    try:
        text = data.decode("utf-8-sig")  # -sig: spreadsheets like to prepend a BOM
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise _err(p, line, f"not UTF-8 text (byte 0x{data[e.start]:02x}); save the table as UTF-8") from None
    # physical lines as an editor numbers them ('\n', with '\r\n' tolerated)
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    lines = [ln.rstrip("\r") for ln in lines]
    if not any(ln.strip() for ln in lines):
        raise _err(p, 1, "empty file (expected '# quantity: ...', a column header line and data rows)")

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
        raise _err(p, 1, "missing header line '# quantity: ...' (one of " + ", ".join(QUANTITIES) + ")")
    quantity = meta["quantity"][0]
    white = 0.99
    if "white_reference" in meta:
        w_text, w_no = meta["white_reference"]
        if quantity != "reflectance_factor":
            raise _err(p, w_no, f"white_reference given for quantity {quantity}; it is only meaningful "
                                "for quantity reflectance_factor")
        try:
            white = float(w_text)
        except ValueError:
            raise _err(p, w_no, f"white_reference = {w_text!r} is not a number") from None
        if not (0.0 < white <= 1.0):  # also rejects nan
            raise _err(p, w_no, f"white_reference = {w_text} is outside (0, 1] "
                                "(a reflectance, e.g. 0.99 for Spectralon, not a percentage)")
    if header_no is None:
        raise _err(p, len(lines), "no column header line (" + _EXPECTED_COLUMNS + ")")

    cols = _parse_header(p, header_no, header)
    if not rows:
        raise _err(p, header_no, "no data rows after the column header")

    n_cols = len(header)
    angle_names = cols["angles"]
    value_idx, sigma_idx, bands = cols["value_idx"], cols["sigma_idx"], cols["bands"]
    n, b = len(rows), len(bands)
    angles = np.empty((n, len(angle_names)))
    values = np.full((n, b), np.nan)
    sigma = np.full((n, b), np.nan) if sigma_idx is not None else None
    mask = np.zeros((n, b), dtype=bool)
    seen: dict[tuple, int] = {}
    for r, (no, cells) in enumerate(rows):
        if len(cells) != n_cols:
            raise _err(p, no, f"row has {len(cells)} cells, expected {n_cols} "
                              f"(one per column of the header on line {header_no})")
        for a, name in enumerate(angle_names):
            angles[r, a] = _angle(p, no, name, cells[cols["angle_idx"][a]], in_plane=cols["in_plane"])
        for k in range(b):
            name, text = header[value_idx[k]], cells[value_idx[k]]
            v = _number(p, no, name, text, allow_missing=True)
            if v is not None:
                values[r, k], mask[r, k] = v, True
            if sigma is not None:
                s_name, s_text = header[sigma_idx[k]], cells[sigma_idx[k]]
                # a missing sample has no uncertainty: its sigma cell may be empty as well
                s = _number(p, no, s_name, s_text, allow_missing=v is None)
                if s is not None:
                    if s < 0:
                        raise _err(p, no, f"{s_name} = {s_text} is negative (a standard deviation is >= 0)")
                    if v is not None:
                        sigma[r, k] = s
        key = _geometry_key(angles[r], angle_names)
        if key in seen:
            raise _err(p, no, f"duplicate of line {seen[key]} (same {', '.join(angle_names)})")
        seen[key] = no

    common = dict(mask=mask, sigma=sigma, quantity=quantity, bands=tuple(bands),
                  wavelengths=cols["wavelengths"], white_reference=white, source=p,
                  masked={MISSING_REASON: int((~mask).sum())} if not mask.all() else {})
    rad = np.deg2rad(angles)
    if cols["in_plane"]:
        return Table.in_plane(rad[:, 0], rad[:, 1], values, **common)
    two_pi = 2 * np.pi
    return Table(theta_i=rad[:, 0], phi_i=np.mod(rad[:, 1], two_pi), theta_o=rad[:, 2],
                 phi_o=np.mod(rad[:, 3], two_pi), values=values, **common)


_KEY_RE = re.compile(r"^#\s*([A-Za-z_][\w-]*)\s*:\s*(.*?)\s*$")
_SCHEMA_RE = re.compile(r"^#\s*appearance-jax\s+table\s+v(\S*)\s*$", re.IGNORECASE)


def _parse_comment(p, no, s, meta, header_no):
    """Record '# quantity:' / '# white_reference:' lines; everything else is a free comment."""
    m = _SCHEMA_RE.match(s)
    if m:
        if m.group(1) != "1":
            raise _err(p, no, f"unsupported schema version 'v{m.group(1)}' (this reader knows "
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
        raise _err(p, no, f"'# {key}: ...' must come before the column header (line {header_no})")
    if key in meta:
        raise _err(p, no, f"second '# {key}:' line (first on line {meta[key][1]})")
    if key == "quantity" and value not in QUANTITIES:
        raise _err(p, no, f"unknown quantity {value!r} (one of {', '.join(QUANTITIES)})")
    meta[key] = (value, no)


def _parse_header(p, no, header):
    """Classify the column names: geometry, value columns (RGB or wavelengths), sigma columns."""
    if len(header) == 1 and ";" in header[0]:
        raise _err(p, no, "columns must be separated by commas, found ';' (re-export the CSV with ',')")
    if all(_is_wavelength(name) for name in header) and len(header) >= 3:
        # a first data row where the column names should be: say so, not 'duplicate column 30'
        raise _err(p, no, f"no column header line: this line looks like data ({_EXPECTED_COLUMNS})")
    index: dict[str, int] = {}
    for c, name in enumerate(header):
        if name == "":
            raise _err(p, no, f"empty column name (column {c + 1})")
        if name in index:
            raise _err(p, no, f"column '{name}' appears twice (columns {index[name] + 1} and {c + 1})")
        index[name] = c
    angle_cols, rgb, spectral, sigmas = [], [], [], []
    for name in header:
        if name in FULL_ANGLES:
            angle_cols.append(name)
        elif name in RGB:
            rgb.append(name)
        elif name.startswith("sigma_"):
            sigmas.append(name)
        elif _is_wavelength(name):
            spectral.append(name)
        else:
            raise _err(p, no, f"unknown column '{name}' ({_EXPECTED_COLUMNS})")

    # geometry: any azimuth column means the full geometry, otherwise in-plane
    in_plane = not ({"phi_i", "phi_o"} & set(angle_cols))
    need = IN_PLANE_ANGLES if in_plane else FULL_ANGLES
    missing = [a for a in need if a not in index]
    if missing:
        raise _err(p, no, f"missing column{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                          "(full geometry needs theta_i, phi_i, theta_o, phi_o; in-plane needs "
                          "theta_i, theta_o)")

    if rgb and spectral:
        raise _err(p, no, f"mixes RGB columns ({', '.join(rgb)}) and spectral columns "
                          f"({', '.join(spectral)}); use one or the other")
    if not rgb and not spectral:
        raise _err(p, no, "no value columns (R,G,B or one column per wavelength in nm)")
    wavelengths = None
    if rgb:
        absent = [c for c in RGB if c not in rgb]
        if absent:
            raise _err(p, no, f"RGB table without column{'s' if len(absent) > 1 else ''} "
                              f"{', '.join(absent)} (R, G and B are all required)")
        bands = list(RGB)
    else:
        bands = spectral
        wl = []
        for name in spectral:
            w = float(name)
            if not math.isfinite(w) or w <= 0:
                raise _err(p, no, f"wavelength column '{name}' is not a positive number of nm")
            if wl and w <= wl[-1]:
                raise _err(p, no, f"wavelength columns must be strictly increasing: '{name}' "
                                  f"after '{spectral[len(wl) - 1]}'")
            wl.append(w)
        wavelengths = np.array(wl)

    sigma_idx = None
    if sigmas:
        by_band = {}
        for s in sigmas:
            band = _sigma_band(s[len("sigma_"):], bands, wavelengths)
            if band is None:
                raise _err(p, no, f"sigma column '{s}' without its value column '{s[len('sigma_'):]}'")
            if band in by_band:
                raise _err(p, no, f"columns '{by_band[band]}' and '{s}' are both the sigma of band {band}")
            by_band[band] = s
        absent = ["sigma_" + bnd for bnd in bands if bnd not in by_band]
        if absent:
            raise _err(p, no, f"missing sigma column{'s' if len(absent) > 1 else ''} {', '.join(absent)} "
                              "(give sigma_<band> for every value column or for none)")
        sigma_idx = [index[by_band[bnd]] for bnd in bands]

    return dict(in_plane=in_plane, angles=need, angle_idx=[index[a] for a in need],
                value_idx=[index[bnd] for bnd in bands], sigma_idx=sigma_idx, bands=bands,
                wavelengths=wavelengths)


def _sigma_band(suffix, bands, wavelengths):
    """The band a ``sigma_<suffix>`` column belongs to (wavelengths compared as numbers)."""
    if suffix in bands:
        return suffix
    if wavelengths is not None and _is_wavelength(suffix):
        hit = np.flatnonzero(wavelengths == float(suffix))
        if hit.size:
            return bands[int(hit[0])]
    return None


def _number(p, no, name, text, allow_missing):
    """float(text); None for a missing cell where allowed; errors name the column and the cell."""
    if text.lower() in MISSING_TOKENS:
        if allow_missing:
            return None
        what = "empty" if text == "" else f"'{text}'"
        kind = "angles are required on every row" if name in FULL_ANGLES else \
            "a sigma is required wherever the value is given"
        raise _err(p, no, f"{name} is {what} ({kind})")
    try:
        v = float(text)
    except ValueError:
        raise _err(p, no, f"{name} = '{text}' is not a number") from None
    if not math.isfinite(v):  # inf, and the nan spellings float() accepts beyond ours (e.g. '-nan')
        raise _err(p, no, f"{name} = {text} is not finite")
    return v


def _angle(p, no, name, text, in_plane):
    v = _number(p, no, name, text, allow_missing=False)
    if name.startswith("phi"):
        lo, hi = 0.0, 360.0
    elif in_plane and name == "theta_o":
        lo, hi = -90.0, 90.0  # signed: < 0 on the retro-reflection side
    else:
        lo, hi = 0.0, 90.0
    if not (lo <= v <= hi):
        raise _err(p, no, f"{name} = {text} is outside [{lo:g}, {hi:g}] degrees")
    return v


def _geometry_key(row_deg, names):
    # round first, then reduce modulo 360, so that 359.9999999999 and 0 coincide
    key = []
    for v, name in zip(row_deg, names):
        r = round(float(v), _DUP_DECIMALS)
        if name.startswith("phi"):
            r = math.fmod(r, 360.0)
        key.append(r + 0.0)  # + 0.0: -0.0 -> 0.0
    return tuple(key)


# ---------------------------------------------------------------------------- writing
def write_csv(table: Table, path, in_plane: bool | None = None) -> None:
    """Write ``table`` in the ``appearance-jax table v1`` schema (docs/tables.md).

    Values and sigma are written as stored, in the table's own quantity, with ``%.9g``
    (9 significant digits); masked samples as empty cells (with empty sigma). Angles are
    written in degrees with 12 significant digits (round trip better than 1e-9 rad).

    Args:
        table: an RGB table (bands R, G, B) or a spectral one (``wavelengths`` set).
        path: output file name.
        in_plane: True: the in-plane variant (theta_i, signed theta_o); the table must be
            in-plane, and the absolute azimuth of the plane of incidence is not kept (isotropy).
            False: the full geometry. None (default): in-plane when the table is in-plane
            and the in-plane file reproduces every direction (plane of incidence at phi_i = 0
            as :meth:`Table.in_plane` builds it), else the full geometry.

    Raises:
        ValueError: the table cannot be written in this schema (bands neither RGB nor
            spectral, in_plane=True for an out-of-plane table, directions below the horizon,
            a valid sample without a finite sigma, no samples).
    """
    if table.spectral:
        wl = np.asarray(table.wavelengths, dtype=np.float64)
        if wl.shape != (table.n_bands,) or not np.all(np.isfinite(wl) & (wl > 0)) or np.any(np.diff(wl) <= 0):
            raise ValueError(f"{table.source}: wavelengths must be {table.n_bands} positive, strictly "
                             "increasing values in nm to be written as CSV columns")
        # keep the band names when they spell the wavelength (round trip of '452.5' vs '452.50')
        names = [b if _is_wavelength(b) and float(b) == w else f"{w:.12g}" for b, w in zip(table.bands, wl)]
    elif table.bands == RGB:
        names = list(RGB)
    else:
        raise ValueError(f"{table.source}: bands {table.bands} are neither R, G, B nor wavelengths; "
                         "the CSV schema has no columns for them")

    if in_plane is None:
        in_plane = table.is_in_plane and _in_plane_lossless(table)
    if in_plane:
        signed = table.signed_theta_o()  # raises for an out-of-plane table
        angle_names = list(IN_PLANE_ANGLES)
        angles = np.stack([table.theta_i, signed], axis=1)
    else:
        angle_names = list(FULL_ANGLES)
        angles = np.stack([table.theta_i, np.mod(table.phi_i, 2 * np.pi), table.theta_o,
                           np.mod(table.phi_o, 2 * np.pi)], axis=1)
    deg = np.rad2deg(angles)
    lo = np.array([0.0, -90.0] if in_plane else [0.0, 0.0, 0.0, 0.0])
    hi = np.array([90.0, 90.0] if in_plane else [90.0, 360.0, 90.0, 360.0])
    outside = np.any((deg < lo - 1e-9) | (deg > hi + 1e-9), axis=1)
    if outside.any():
        # e.g. the below-horizon nodes that merl_table keeps (masked); never dropped silently
        r = int(np.flatnonzero(outside)[0])
        raise ValueError(f"{table.source}: {int(outside.sum())} rows have angles outside the schema's ranges "
                         f"(first: row {r}, {dict(zip(angle_names, np.round(deg[r], 6).tolist()))} degrees), "
                         "e.g. directions below the horizon; select the rows to write first, e.g. "
                         "table.select(table.mask.any(axis=1))")
    deg = np.clip(deg, lo, hi)  # float noise at the range ends (90.00000000000001)
    if table.n_samples == 0:
        raise ValueError(f"{table.source}: no samples to write (a table file needs at least one data row)")

    out = [SCHEMA_LINE, f"# quantity: {table.quantity}"]
    if table.quantity == "reflectance_factor":
        out.append(f"# white_reference: {table.white_reference:.12g}")
    out.append("# source: " + " ".join(str(table.source).split()))  # one line, whatever the name
    for why, count in table.masked.items():
        out.append("# masked: " + " ".join(f"{count} {why}".split()))
    columns = angle_names + names
    if table.sigma is not None:
        columns += ["sigma_" + nm for nm in names]
    out.append(",".join(columns))

    def fmt(v, ok):
        return f"{v:.9g}" if ok else ""

    sig = table.sigma
    if sig is not None:
        bad = table.mask & ~(np.isfinite(sig) & (sig >= 0))
        if bad.any():
            r, k = np.argwhere(bad)[0]
            raise ValueError(f"{table.source}: sigma of sample {r}, band {table.bands[k]} is {sig[r, k]!r}; "
                             "every valid sample needs a finite sigma >= 0 to be written")
    for r in range(table.n_samples):
        cells = [f"{d + 0.0:.12g}" for d in deg[r]]  # + 0.0: no '-0'
        ok = table.mask[r]
        cells += [fmt(v, m) for v, m in zip(table.values[r], ok)]
        if sig is not None:
            cells += [fmt(s, m) for s, m in zip(sig[r], ok)]  # a masked sample has no sigma
        out.append(",".join(cells))
    with open(os.fspath(path), "w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(out) + "\n")


def _in_plane_lossless(table: Table) -> bool:
    """Whether the in-plane variant (phi_i = 0) reproduces every direction to 1e-9 rad."""
    def unit(theta, phi):
        return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])

    rebuilt = Table.in_plane(table.theta_i, table.signed_theta_o(), table.values)
    # compare directions, not angles: the azimuth of a direction along the normal is arbitrary
    return bool(np.all(np.abs(unit(table.theta_i, table.phi_i) - unit(rebuilt.theta_i, rebuilt.phi_i)) < 1e-9)
                and np.all(np.abs(unit(table.theta_o, table.phi_o) - unit(rebuilt.theta_o, rebuilt.phi_o)) < 1e-9))
