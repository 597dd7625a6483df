"""Read any table the fitters accept from one text specification (command line, notebooks).

    table = read_table("velvet.csv")                   # appearance-jax table v1 CSV
    table = read_table("gold-metallic-paint.binary")   # MERL file, every 3rd bin
    table = read_table("proxy:white-fabric")           # Neural-BRDF proxy, gonio grid
    table = read_table("proxy:white-fabric:in_plane")  # ... on the in-plane grid

Accepted forms of ``spec`` (:data:`FORMS`):

==============================  ===============================================================
``PATH.csv``                    :func:`~appearance_jax.fit.tables.csv_table.read_csv`
``PATH.binary``                 :func:`~appearance_jax.fit.tables.merl.read_merl_table` with ``stride``
                                (default :data:`DEFAULT_MERL_STRIDE` = 3: 30 x 30 x 60 nodes,
                                54 000 directions of which about half above the horizon; the
                                full resolution, stride 1, has 1.46 million directions and
                                makes a fit slow and memory-hungry for no gain with the
                                smooth analytic models fitted here)
``proxy:NAME[:GRID]``           :func:`~appearance_jax.fit.tables.proxy.proxy_table` of a MERL
                                Neural-BRDF **proxy** (not a measurement); GRID one of
                                ``gonio`` (default), ``in_plane``, ``merl``; ``stride`` applies
                                to the ``merl`` grid only (default 5 there)
==============================  ===============================================================

File extensions are matched case-insensitively. Errors: an unknown form is a ``ValueError``
listing these forms; a missing file a ``FileNotFoundError`` naming the path; a malformed file
a :class:`~appearance_jax.fit.tables.csv_table.TableError` (a ``ValueError``) from its reader; an
unknown proxy name a ``ValueError`` with close matches.
"""

from __future__ import annotations

import os

from .csv_table import TableError, read_csv, write_csv
from .table import Table

__all__ = ["read_table", "write_table", "DEFAULT_MERL_STRIDE", "PROXY_GRIDS", "FORMS", "TableError"]

DEFAULT_MERL_STRIDE = 3
PROXY_GRIDS = ("gonio", "in_plane", "merl")
FORMS = ("PATH.csv (appearance-jax table v1)",
         f"PATH.binary (MERL; stride default {DEFAULT_MERL_STRIDE})",
         "proxy:NAME or proxy:NAME:GRID (Neural-BRDF proxy of a MERL material; GRID gonio|in_plane|merl)")


def _forms() -> str:
    return "; ".join(FORMS)


def _check_file(p: str) -> None:
    if not os.path.exists(p):
        raise FileNotFoundError(f"table file not found: {p}")
    if os.path.isdir(p):
        raise ValueError(f"{p} is a directory, not a table file")


def read_table(spec, *, stride: int | None = None, max_bytes: int | None = None) -> Table:
    """A :class:`~appearance_jax.fit.tables.table.Table` from ``spec`` (see the module docstring).

    Args:
        spec: a path (str or path-like) ending ``.csv`` or ``.binary``, or ``proxy:NAME[:GRID]``.
        stride: MERL bin stride for ``.binary`` files (default 3) and ``proxy:NAME:merl``
            (default 5); must divide 90 and 180. Given for any other form it is an error
            (it would be silently ignored otherwise).
        max_bytes: size limit of a ``.csv`` file (default
            :data:`~appearance_jax.fit.tables.csv_table.MAX_CSV_BYTES`, 64 MiB), checked before
            reading; CSV only (a MERL file has a fixed size).

    Raises:
        ValueError: unknown form, unknown proxy name or grid, misplaced or invalid ``stride``.
        FileNotFoundError: the file does not exist (the message names the path).
        TableError: the file is malformed (from the reader, with file and line).
    """
    if stride is not None and (isinstance(stride, bool) or int(stride) != stride or stride < 1):
        raise ValueError(f"stride = {stride!r}: must be a positive integer dividing 90 and 180")
    text = os.fspath(spec)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    low = text.lower()
    if max_bytes is not None and not low.endswith(".csv"):
        raise ValueError(f"{text}: max_bytes applies to .csv tables only")
    if text.startswith("proxy:"):
        return _read_proxy(text, stride)
    if low.endswith(".csv"):
        if stride is not None:
            raise ValueError(f"{text}: stride applies to MERL .binary files and proxy:NAME:merl, not to CSV tables")
        _check_file(text)
        return read_csv(text, max_bytes=max_bytes)
    if low.endswith(".binary"):
        _check_file(text)
        from .merl import read_merl_table

        return read_merl_table(text, DEFAULT_MERL_STRIDE if stride is None else int(stride))
    raise ValueError(f"cannot read a table from {text!r}: accepted forms are {_forms()}")


def _read_proxy(text: str, stride: int | None) -> Table:
    parts = text.split(":")
    if len(parts) not in (2, 3) or not parts[1]:
        raise ValueError(f"{text!r}: expected proxy:NAME or proxy:NAME:GRID (GRID {'|'.join(PROXY_GRIDS)}), "
                         "e.g. proxy:white-fabric:in_plane")
    name = parts[1]
    grid = parts[2] if len(parts) == 3 else "gonio"
    if grid not in PROXY_GRIDS:
        raise ValueError(f"{text!r}: unknown proxy grid {grid!r}; use one of {', '.join(PROXY_GRIDS)}")
    if stride is not None and grid != "merl":
        raise ValueError(f"{text!r}: stride applies to the merl grid only (proxy:{name}:merl)")
    from . import proxy

    kw = {} if stride is None else {"stride": int(stride)}
    try:
        return proxy.proxy_table(name, grid, **kw)
    except KeyError as e:  # unknown material: a ValueError with the proxy's own message (close matches)
        raise ValueError(e.args[0] if e.args else str(e)) from None


def write_table(table: Table, path, in_plane: bool | None = None) -> None:
    """Write ``table`` as an appearance-jax table v1 CSV (:func:`~appearance_jax.fit.tables.csv_table.write_csv`)."""
    write_csv(table, path, in_plane=in_plane)
