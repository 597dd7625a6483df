"""MERL BRDF database files (``.binary``, Matusik et al. 2003, "A data-driven reflectance model").

File layout (all little-endian):

- header: 3 x int32, the bin counts (n_theta_h, n_theta_d, n_phi_d) = (90, 90, 180);
- body: 3 x 90 x 90 x 180 float64, channel-major (all R, then all G, then all B), each
  channel in C order over (theta_h, theta_d, phi_d): 34 992 012 bytes in all.

A stored value times the channel scale (1/1500, 1.15/1500, 1.66/1500) for (R, G, B) is the
BRDF in 1/sr. **Negative** stored values mark samples that were not measured; they become
NaN here and masked samples in a :class:`~appearance_jax.fit.tables.table.Table`, never zeros.

Bins (Rusinkiewicz half/difference angles, phi_h = 0 by isotropy):

- theta_h in [0, pi/2): index floor(sqrt(theta_h / (pi/2)) * 90), denser near the highlight;
- theta_d in [0, pi/2): index floor(theta_d / (pi/2) * 90), 1 degree bins;
- phi_d in [0, pi): index floor(phi_d / pi * 180), 1 degree bins; phi_d and phi_d + pi are
  the same sample (reciprocity), so phi_d is folded modulo pi.

:func:`lookup` applies these rules; :func:`merl_table` samples the nodes of
:func:`~appearance_jax.fit.tables.grids.merl_angles` (the lower edge of each bin).

Errors are :class:`~appearance_jax.fit.tables.csv_table.TableError` with the message
``{path}: {problem}`` (a binary file has no line numbers, so there is no ``:line``).
"""

from __future__ import annotations

import os

import numpy as np

from ...core.files import FileProblem, check_output_path, open_regular_file
from .csv_table import TableError
from .grids import MERL_SHAPE, half_diff_to_angles, merl_angles
from .table import Table

__all__ = ["MERL_SCALE", "MERL_FILE_BYTES", "read_merl", "write_merl", "merl_table",
           "read_merl_table", "lookup", "merl_indices"]

MERL_SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])  # stored value -> 1/sr, (R, G, B)
_HEADER_BYTES = 3 * 4
_N_VALUES = 3 * int(np.prod(MERL_SHAPE))
MERL_FILE_BYTES = _HEADER_BYTES + 8 * _N_VALUES
BRDF_SHAPE = MERL_SHAPE + (3,)
BELOW_HORIZON = "below horizon"
MISSING = "missing (negative in MERL file)"
# Index slack (in bins) so that the node angles of grids.merl_angles (the exact lower bin
# edges) map to their own bin: in float64 sqrt(theta_h/(pi/2))*90 at node i is sometimes
# i - 1e-14, and a bare floor would return bin i - 1 (it does for 9 of the 90 theta_h nodes).
_INDEX_SLACK = 1e-6


def read_merl(path) -> np.ndarray:
    """Read a MERL ``.binary`` file.

    Args:
        path: file name.

    Returns:
        float64 array of shape (90, 90, 180, 3), indexed (theta_h, theta_d, phi_d, channel),
        BRDF in 1/sr (linear RGB); NaN where the file has a negative (missing) sample.

    Raises:
        TableError: ``{path}: ...`` for a file that is not a regular file (a FIFO, a device: refused
            before it is opened), a short file, a wrong header, a wrong size (header and size are
            checked before the body is read) or NaN/inf values.
        OSError: the file does not exist or cannot be read.
    """
    p = os.fspath(path)
    try:
        f, size = open_regular_file(p)  # a FIFO or device is refused before it is opened
    except FileProblem as e:
        raise TableError(f"{p}: {e.problem} (a MERL .binary file is expected)") from None
    with f:
        # header and size are checked before the body is read: a large file that is not a
        # MERL file costs 12 bytes of reading, not its size in memory
        head = f.read(_HEADER_BYTES) if size >= _HEADER_BYTES else b""
        if len(head) != _HEADER_BYTES:
            raise TableError(f"{p}: {len(head) if head else size} bytes, too short for the MERL header "
                             f"({_HEADER_BYTES} bytes: 3 x int32 bin counts)")
        header = tuple(int(v) for v in np.frombuffer(head, dtype="<i4", count=3))
        if header != MERL_SHAPE:
            raise TableError(f"{p}: MERL header gives bin counts {header}, expected {MERL_SHAPE} "
                             "(not a MERL .binary file, or a different resolution)")
        # the body is read only when the size is right (re-checked: the file may change meanwhile)
        body = f.read(MERL_FILE_BYTES - _HEADER_BYTES + 1) if size == MERL_FILE_BYTES else b""
        if size != MERL_FILE_BYTES or len(body) != MERL_FILE_BYTES - _HEADER_BYTES:
            got = size if size != MERL_FILE_BYTES else _HEADER_BYTES + len(body)
            raise TableError(f"{p}: file has {got} bytes, expected {MERL_FILE_BYTES} "
                             f"(12-byte header + 3 x 90 x 90 x 180 float64)")
    raw = np.frombuffer(body, dtype="<f8").reshape((3,) + MERL_SHAPE)
    bad = ~np.isfinite(raw)
    if bad.any():
        c, i, j, k = (int(x) for x in np.argwhere(bad)[0])
        raise TableError(f"{p}: {int(bad.sum())} NaN/inf values (first in channel {'RGB'[c]} at bin "
                         f"theta_h={i}, theta_d={j}, phi_d={k}); MERL marks missing samples with "
                         "negative values, NaN/inf means a corrupt file")
    brdf = np.where(raw < 0, np.nan, raw * MERL_SCALE[:, None, None, None])
    return np.ascontiguousarray(np.moveaxis(brdf, 0, -1))


def write_merl(path, brdf) -> None:
    """Write a BRDF (1/sr) in the MERL ``.binary`` format; NaN samples are written as -1.0 (missing).

    ``read_merl(path)`` returns ``brdf`` to within 1 ulp (stored = brdf / scale, read back as
    stored * scale), and in practice bit-exactly when ``brdf`` itself came from
    :func:`read_merl` (no counterexample in 6e7 random stored values; the stored values may
    differ from the original file's by an ulp, the BRDF read back does not).

    Args:
        path: output file name.
        brdf: (90, 90, 180, 3) array, (theta_h, theta_d, phi_d, R/G/B), finite and >= 0 or NaN.

    Raises:
        ValueError: wrong shape, inf, or negative values (they would read back as missing), or
            ``path`` exists and is not a regular file (a FIFO, a device, a directory).
    """
    f = np.asarray(brdf, dtype=np.float64)
    if f.shape != BRDF_SHAPE:
        raise ValueError(f"write_merl: brdf has shape {f.shape}, expected {BRDF_SHAPE} "
                         "(theta_h, theta_d, phi_d, RGB)")
    if np.isinf(f).any():
        raise ValueError("write_merl: brdf has inf values")
    if (f < 0).any():
        raise ValueError(f"write_merl: brdf has {int((f < 0).sum())} negative values; MERL would read "
                         "them as missing samples (use NaN for missing)")
    f = np.moveaxis(f, -1, 0)  # channel-major
    raw = np.where(np.isnan(f), -1.0, f / MERL_SCALE[:, None, None, None])
    try:
        check_output_path(path)  # opening a FIFO for writing would block
    except FileProblem as e:
        raise ValueError(f"write_merl: {os.fspath(path)} {e.problem}") from None
    with open(os.fspath(path), "wb") as out:
        out.write(np.asarray(MERL_SHAPE, dtype="<i4").tobytes())
        out.write(np.ascontiguousarray(raw, dtype="<f8").tobytes())


def merl_table(brdf, stride: int = 1, source: str = "<memory>") -> Table:
    """A :class:`Table` (quantity ``brdf``, bands R, G, B) of a MERL BRDF at the grid nodes.

    Samples every ``stride``-th bin of each axis at the nodes of
    :func:`~appearance_jax.fit.tables.grids.merl_angles` (phi_h = 0), converted to
    (theta_i, phi_i, theta_o, phi_o) by :func:`~appearance_jax.fit.tables.grids.half_diff_to_angles`.
    Every node is a row; nothing is dropped. Masked, with the count of band entries per reason
    in ``Table.masked`` (reasons with a count of 0 are left out):

    - ``"below horizon"``: wi or wo at or below the horizon (all 3 bands);
    - ``"missing (negative in MERL file)"``: NaN samples at nodes above the horizon (a node
      below the horizon is counted there only).

    Args:
        brdf: (90, 90, 180, 3) BRDF in 1/sr as returned by :func:`read_merl`.
        stride: bin step, must divide 90 (1 -> 1 458 000 rows, 5 -> 11 664).
        source: recorded as ``Table.source``.
    """
    f = np.asarray(brdf, dtype=np.float64)
    if f.shape != BRDF_SHAPE:
        raise ValueError(f"merl_table: brdf has shape {f.shape}, expected {BRDF_SHAPE}")
    theta_h, theta_d, phi_d = merl_angles(stride)
    ti, pi_, to, po, above = half_diff_to_angles(theta_h.ravel(), theta_d.ravel(), phi_d.ravel())
    values = f[::stride, ::stride, ::stride].reshape(-1, 3)
    present = np.isfinite(values)
    mask = present & above[:, None]
    masked = {}
    n_below = 3 * int((~above).sum())
    n_missing = int((~present & above[:, None]).sum())
    if n_below:
        masked[BELOW_HORIZON] = n_below
    if n_missing:
        masked[MISSING] = n_missing
    return Table(theta_i=ti, phi_i=pi_, theta_o=to, phi_o=po, values=values, mask=mask,
                 quantity="brdf", bands=("R", "G", "B"), source=str(source), masked=masked)


def read_merl_table(path, stride: int = 1) -> Table:
    """:func:`merl_table` of :func:`read_merl` ``(path)``, with ``source = path``."""
    return merl_table(read_merl(path), stride, source=os.fspath(path))


def merl_indices(theta_h, theta_d, phi_d):
    """MERL bin indices (i, j, k) of half/difference angles in radians (numpy, broadcasting).

    floor of the fractional index, clipped to the table (so theta_h < 0 -> 0, theta >= pi/2 ->
    last bin), with phi_d folded modulo pi; a slack of 1e-6 bin keeps the exact bin edges
    (the nodes of :func:`~appearance_jax.fit.tables.grids.merl_angles`) in their own bin despite
    float rounding. Angles must be finite.
    """
    th = np.asarray(theta_h, dtype=np.float64)
    td = np.asarray(theta_d, dtype=np.float64)
    pd = np.mod(np.asarray(phi_d, dtype=np.float64), np.pi)
    n_h, n_d, n_p = MERL_SHAPE
    x_h = np.sqrt(np.maximum(th, 0.0) / (np.pi / 2)) * n_h
    x_d = td / (np.pi / 2) * n_d
    x_p = pd / np.pi * n_p
    i = np.clip(np.floor(x_h + _INDEX_SLACK), 0, n_h - 1).astype(np.intp)
    j = np.clip(np.floor(x_d + _INDEX_SLACK), 0, n_d - 1).astype(np.intp)
    k = np.clip(np.floor(x_p + _INDEX_SLACK), 0, n_p - 1).astype(np.intp)
    # mod can return pi itself for phi_d just below a multiple of pi; that is bin 0 after folding
    k = np.where(x_p + _INDEX_SLACK >= n_p, 0, k)
    return i, j, k


def lookup(brdf, theta_h, theta_d, phi_d) -> np.ndarray:
    """Nearest-bin value of a MERL BRDF at half/difference angles (radians), numpy.

    Args:
        brdf: (90, 90, 180, 3) array from :func:`read_merl`.
        theta_h, theta_d, phi_d: broadcastable angle arrays in radians (phi_h = 0 assumed,
            the material is isotropic).

    Returns:
        array of shape broadcast(...) + (3,), BRDF in 1/sr (NaN where the file is missing).
    """
    f = np.asarray(brdf)
    if f.shape != BRDF_SHAPE:
        raise ValueError(f"lookup: brdf has shape {f.shape}, expected {BRDF_SHAPE}")
    i, j, k = np.broadcast_arrays(*merl_indices(theta_h, theta_d, phi_d))
    return f[i, j, k]
