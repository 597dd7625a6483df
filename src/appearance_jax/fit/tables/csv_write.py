"""Writing tables in the ``appearance-jax table v1`` CSV schema (docs/tables.md).

:func:`write_csv` is the one writer of the schema that
:func:`~appearance_jax.fit.tables.csv_table.read_csv` reads (it is re-exported there).
"""

from __future__ import annotations

import os

import numpy as np

from ...core.files import FileProblem, check_output_path
from .csv_cells import FULL_ANGLES, IN_PLANE_ANGLES, RGB, SCHEMA_LINE, is_wavelength
from .table import Table

__all__ = ["write_csv"]


def write_csv(table: Table, path, in_plane: bool | None = None) -> None:
    """Write ``table`` in the ``appearance-jax table v1`` schema (docs/tables.md).

    Values and sigma are written as stored, in the table's own quantity, with ``%.9g``
    (9 significant digits); masked samples as empty cells (with empty sigma). Negative values
    are written as they are, and :func:`~appearance_jax.fit.tables.csv_table.read_csv` masks
    them (reason ``"negative value"``: not a BRDF value). Angles are
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
            a valid sample without a finite sigma, no samples), or ``path`` exists and is not a
            regular file (a FIFO, a device, a directory).
    """
    if table.spectral:
        wl = np.asarray(table.wavelengths, dtype=np.float64)
        if wl.shape != (table.n_bands,) or not np.all(np.isfinite(wl) & (wl > 0)) or np.any(np.diff(wl) <= 0):
            raise ValueError(f"{table.source}: wavelengths must be {table.n_bands} positive, strictly "
                             "increasing values in nm to be written as CSV columns")
        # keep the band names when they spell the wavelength (round trip of '452.5' vs '452.50')
        names = [b if is_wavelength(b) and float(b) == w else f"{w:.12g}" for b, w in zip(table.bands, wl)]
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
    try:
        check_output_path(path)  # opening a FIFO for writing would block
    except FileProblem as e:
        raise ValueError(f"write_csv: {os.fspath(path)} {e.problem}") from None
    with open(os.fspath(path), "w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(out) + "\n")


def _in_plane_lossless(table: Table) -> bool:
    """Whether the in-plane variant (phi_i = 0) reproduces every direction to 1e-9 rad."""
    def unit(theta, phi):
        return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])

    # the directions Table.in_plane would rebuild (phi_i = 0, phi_o = pi on the forward side);
    # built directly so that any band count works (a Table needs band names for its values)
    to = table.signed_theta_o()
    phi_o = np.where(to >= 0, np.pi, 0.0)
    # compare directions, not angles: the azimuth of a direction along the normal is arbitrary
    return bool(np.all(np.abs(unit(table.theta_i, table.phi_i) - unit(table.theta_i, 0.0 * table.theta_i)) < 1e-9)
                and np.all(np.abs(unit(table.theta_o, table.phi_o) - unit(np.abs(to), phi_o)) < 1e-9))
