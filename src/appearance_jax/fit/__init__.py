"""Fitting: measurement tables in, parameters with uncertainties and plots out (DESIGN.md, Fitting).

The usual path::

    table = read_table("my_gonio.csv")             # fit.tables.io: CSV, MERL .binary, "proxy:NAME[:GRID]"
    result = fit("rough_plastic", table, fix={"eta": 1.5})
    write_report(result, "out/fit")

One subpackage per job: ``tables`` (the Table record; reading, writing and converting CSV,
MERL .binary and Neural-BRDF proxy tables), ``solve`` (residual metrics, parameter spaces, the
solvers and uncertainties, batched fits) and ``report`` (params.json, residuals.csv, figures).
"""

from .report import write_report
from .solve import BatchFitResult, FitResult, fit, fit_batch
from .tables import Table, TableError, proxy, read_csv, read_table, write_csv, write_table

__all__ = ["Table", "TableError", "read_csv", "write_csv", "read_table", "write_table", "fit", "FitResult",
           "fit_batch", "BatchFitResult", "write_report", "proxy"]
