"""Cells and names of the ``appearance-jax table v1`` CSV schema: the error type, the column
names, the reasons a value is masked, and the strict number syntax (docs/tables.md, "Cells").

A number cell is plain decimal text, ``[+-]digits[.digits][e[+-]digits]`` (ASCII digits):
Python's ``float`` accepts more (``1_0`` is 10.0, ``١٠`` is 10.0, ``infinity``, ``  1 ``), and
a table cell that only ``float`` would read is far more likely a typo or a unit than a
number, so it is an error naming the column and the text.
"""

from __future__ import annotations

import math
import re

__all__ = ["TableError", "err_at", "SCHEMA_LINE", "FULL_ANGLES", "IN_PLANE_ANGLES", "RGB", "MISSING_TOKENS",
           "MISSING_REASON", "EMPTY_ROW_REASON", "NEGATIVE_REASON", "parse_number", "is_wavelength",
           "number_cell", "angle_cell"]

SCHEMA_LINE = "# appearance-jax table v1"
FULL_ANGLES = ("theta_i", "phi_i", "theta_o", "phi_o")
IN_PLANE_ANGLES = ("theta_i", "theta_o")
RGB = ("R", "G", "B")
MISSING_TOKENS = ("", "nan", "na")  # compared lower-case
# Table.masked reasons of read_csv (counts of band entries)
MISSING_REASON = "missing value"
EMPTY_ROW_REASON = "missing value (whole row)"
NEGATIVE_REASON = "negative value"

_NUMBER = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_NUMBER_RE = re.compile(_NUMBER + r"\Z")
_UNIT_RE = re.compile(r"(" + _NUMBER + r")\s*([^\s0-9_.+\-].*)\Z")  # '30deg', '0.5 1/sr' is not one
_NON_FINITE = ("inf", "infinity", "nan")


class TableError(ValueError):
    """A malformed measurement file. The message starts with ``{path}:{line}: `` for a problem at
    a line of a text file, or with ``{path}: `` for a problem of the whole file (not a regular
    file, too large) and for binary files such as MERL ``.binary``, which have no lines."""


def err_at(path, line, msg) -> TableError:
    """``TableError("{path}:{line}: {msg}")``."""
    return TableError(f"{path}:{line}: {msg}")


def parse_number(text: str) -> float | None:
    """The value of a plain decimal number (see the module docstring), else None."""
    return float(text) if _NUMBER_RE.match(text) else None


def is_wavelength(name: str) -> bool:
    """Whether a column name is a wavelength (a plain number, in nm)."""
    return parse_number(name) is not None


def _not_a_number(name: str, text: str) -> str:
    """Why ``text`` in column ``name`` is not a number, with a hint where one helps."""
    if text.lstrip("+-").lower() in _NON_FINITE:
        return f"{name} = {text} is not finite"
    m = _UNIT_RE.match(text)
    if m:
        return (f"{name} = '{text}' is not a plain number (unit or text '{m.group(2)}' after {m.group(1)}? "
                "cells hold numbers only: angles in degrees, values in the unit of the quantity)")
    if "_" in text and parse_number(text.replace("_", "")) is not None:
        return f"{name} = '{text}' is not a plain number (digit separators '_' are not accepted)"
    if math.isfinite(_py_float(text)):
        return f"{name} = '{text}' is not a plain number (write ASCII digits, e.g. 0.25 or 1e-3)"
    return f"{name} = '{text}' is not a number"


def _py_float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return math.nan


def number_cell(p, no, name, text, allow_missing):
    """The number in a cell; None for a missing cell where allowed; errors name the column and the cell."""
    if text.lower() in MISSING_TOKENS:
        if allow_missing:
            return None
        what = "empty" if text == "" else f"'{text}'"
        kind = "angles are required on every row" if name in FULL_ANGLES else \
            "a sigma is required wherever the value is given"
        raise err_at(p, no, f"{name} is {what} ({kind})")
    v = parse_number(text)
    if v is None:
        raise err_at(p, no, _not_a_number(name, text))
    if not math.isfinite(v):  # 1e999
        raise err_at(p, no, f"{name} = {text} is not finite")
    return v


def angle_cell(p, no, name, text, in_plane):
    """An angle cell in degrees, checked against its column's range."""
    v = number_cell(p, no, name, text, allow_missing=False)
    if name.startswith("phi"):
        lo, hi = 0.0, 360.0
    elif in_plane and name == "theta_o":
        lo, hi = -90.0, 90.0  # signed: < 0 on the retro-reflection side
    else:
        lo, hi = 0.0, 90.0
    if not (lo <= v <= hi):
        raise err_at(p, no, f"{name} = {text} is outside [{lo:g}, {hi:g}] degrees")
    return v
