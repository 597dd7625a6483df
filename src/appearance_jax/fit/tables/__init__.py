"""Measurement tables: the :class:`Table` record, reading, writing and converting them.

Modules: ``table`` (the Table record, unit conversions, in-plane geometry), ``csv_table`` (the
CSV schema: reading), ``csv_write`` (writing it), ``csv_cells`` (its error type, column names,
mask reasons and strict number syntax), ``merl`` (MERL .binary), ``proxy`` (Neural-BRDF
proxies of MERL), ``grids`` (angle grids) and ``io`` (dispatch on the file name:
:func:`read_table`, :func:`write_table`).
"""

from .csv_table import TableError, read_csv, write_csv
from .io import read_table, write_table
from .table import Table

__all__ = ["Table", "TableError", "read_csv", "write_csv", "read_table", "write_table"]
