"""Fitting: measurement tables in, parameters with uncertainties and plots out (DESIGN.md, Fitting).

The usual path::

    table = read_table("my_gonio.csv")             # fit.io: CSV, MERL .binary, "proxy:NAME[:GRID]"
    result = fit("rough_plastic", table, fix={"eta": 1.5})
    write_report(result, "out/fit")

Modules: ``table`` (the Table record and unit conversions), ``csv_table`` (the CSV schema),
``merl`` (MERL .binary), ``proxy`` (Neural-BRDF proxies of MERL), ``grids`` (angle grids),
``io`` (dispatch), ``residuals`` (metrics), ``transforms`` (parameter spaces), ``solve``
(fit, uncertainties), ``batch`` (vmap + sharding), ``report`` (params.json, residuals.csv, plots).
"""

from .batch import BatchFitResult, fit_batch
from .csv_table import TableError, read_csv, write_csv
from .io import read_table, write_table
from .report import write_report
from .solve import FitResult, fit
from .table import Table

__all__ = ["Table", "TableError", "read_csv", "write_csv", "read_table", "write_table", "fit", "FitResult",
           "fit_batch", "BatchFitResult", "write_report"]
