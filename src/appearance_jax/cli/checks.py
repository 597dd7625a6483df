"""Checks of the command line's options, run before a table is read or anything is compiled.

Every check raises :class:`UsageError` (a ``ValueError``) whose message names the option, the
value given and what is valid; :func:`appearance_jax.cli.main` prints it on one stderr line
and exits with :data:`EXIT_USAGE`. The exit codes of the command line are defined here.
"""

from __future__ import annotations

import difflib
import math
import os

import numpy as np

#: the run did what was asked (a fit: the solver converged)
EXIT_OK = 0
#: an unexpected failure while running (e.g. the report could not be written)
EXIT_FAILURE = 1
#: invalid command line or input: a bad option value, an unknown model, a missing or malformed
#: table (argparse's own usage errors exit with 2 too)
EXIT_USAGE = 2
#: fit only: the solver stopped without converging; the report is written all the same
EXIT_NOT_CONVERGED = 3

EXIT_CODES = {
    EXIT_OK: "success (fit: the solver converged)",
    EXIT_FAILURE: "failure while running (e.g. a file could not be written)",
    EXIT_USAGE: "invalid command line or input (option value, model name, table file); nothing was computed",
    EXIT_NOT_CONVERGED: "fit: the solver did not converge (report written; params.json has converged: false) or diverged to non-finite parameters (no report)",
}


class UsageError(ValueError):
    """A bad option value; the message names the option, the value and what is valid."""


# ------------------------------------------------------------------------- numbers, folders
def count(option: str, value, lo: int = 1, zero: bool = False) -> int:
    """An integer option ``>= lo`` (or 0 with ``zero``)."""
    if zero and value == 0 and not isinstance(value, bool):
        return 0
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise UsageError(f"{option} {value}: must be " + ("0 or " if zero else "") + f"an integer >= {lo}")
    return int(value)


def out_folder(option: str, path: str) -> str:
    """A folder to write into: it may be missing (it is created) but must not be a file."""
    if os.path.exists(path) and not os.path.isdir(path):
        raise UsageError(f"{option} {path}: is an existing file; give a folder (created if it does not exist)")
    return path


def stride(value) -> int | None:
    """``--stride``: None, or a positive integer dividing 90 and 180 (MERL bins)."""
    if value is None:
        return None
    if isinstance(value, bool) or value < 1 or 90 % value:
        ok = ", ".join(str(d) for d in range(1, 91) if 90 % d == 0)
        raise UsageError(f"--stride {value}: must be a positive integer dividing 90 and 180 ({ok})")
    return int(value)


def table_spec(spec: str, stride_value) -> None:
    """A table argument that names an existing file of a known form (or ``proxy:...``), and a
    ``--stride`` that fits it; the file is not read (:func:`~appearance_jax.fit.tables.io.read_table`
    reads it and checks its content)."""
    from ..fit.tables.io import FORMS

    low = spec.lower()
    if spec.startswith("proxy:"):
        return
    if not (low.endswith(".csv") or low.endswith(".binary")):
        raise UsageError(f"table {spec!r}: cannot read a table from it; accepted forms are {'; '.join(FORMS)}")
    if stride_value is not None and low.endswith(".csv"):
        raise UsageError(f"--stride {stride_value}: the stride applies to MERL .binary files and "
                         "proxy:NAME:merl, not to CSV tables")
    if not os.path.exists(spec):
        raise UsageError(f"table file not found: {spec}")
    if os.path.isdir(spec):
        raise UsageError(f"table {spec}: is a directory, not a table file")


# ------------------------------------------------------------------------- models
def model(name: str, purpose: str | None = None, option: str = "--model"):
    """The registered model ``name`` (``a+b`` sums too), a BSDF unless ``purpose`` is None;
    an unknown name gets close matches."""
    from .. import registry

    try:
        m = registry.get(name)
    except KeyError as e:
        msg = e.args[0] if e.args else str(e)
        parts = [p.strip() for p in name.split("+")] if "+" in name else [name]
        close = []
        for part in parts:
            if part not in registry.names():
                close += difflib.get_close_matches(part, registry.names(), n=3, cutoff=0.6)
        hint = f"; did you mean {' or '.join(dict.fromkeys(close))}?" if close else ""
        raise UsageError(f"{option} {name}: {msg}{hint}") from None
    if purpose is not None and m.kind != "bsdf":
        raise UsageError(f"{option} {name}: {m.name} is a {m.kind}; {purpose} BSDFs (appearance-jax models "
                         "lists the kinds)")
    return m


def parse_value(text: str):
    """A command-line value: a number, a comma list (bands) of numbers, true/false, or text."""
    text = text.strip()
    if "," in text:
        try:
            return tuple(float(x) for x in text.split(","))
        except ValueError:
            raise UsageError(f"{text!r}: a comma list must hold numbers only (e.g. 0.8,0.5,0.2)") from None
    try:
        return float(text)
    except ValueError:
        if text.lower() in ("true", "false"):
            return text.lower() == "true"
        return text


def assignments(option: str, items) -> dict:
    """``NAME=VALUE`` items -> {name: value}."""
    kw = {}
    for a in items or []:
        if "=" not in a or not a.split("=", 1)[0].strip():
            raise UsageError(f"{option} {a!r}: expected name=value (e.g. alpha=0.2 or reflectance=0.8,0.5,0.2)")
        k, v = a.split("=", 1)
        try:
            kw[k.strip()] = parse_value(v)
        except UsageError as e:
            raise UsageError(f"{option} {a}: {e}") from None
    return kw


def params(model, items, preset: str | None = None):
    """Params from ``--param name=value`` (``preset=P`` among them, or ``preset``, picks the base);
    a value out of range names ``--param`` and the valid range."""
    from ..core.params import validate

    kw = assignments("--param", items)
    preset = kw.pop("preset", preset)
    names = list(model.Params.__dataclass_fields__)
    if preset is not None:
        if preset not in model.presets:
            raise UsageError(f"--preset {preset}: {model.name}: no preset {preset!r}; presets: "
                             f"{', '.join(model.presets) or 'none'}")
        base = model.presets[preset]
    else:
        base = model.Params()
    unknown = [k for k in kw if k not in names]
    if unknown:
        raise UsageError(f"--param {unknown[0]}: {model.name}: unknown parameter(s) {', '.join(unknown)}; "
                         f"parameters are {', '.join(names)}")
    try:
        p = base.replace(**kw) if kw else base
        validate(p)
    except (ValueError, TypeError) as e:
        raise UsageError(f"--param: {e}") from None
    return p


def parse_fix(items) -> dict:
    """``--fix name=value`` (fix at value) and ``--fix name`` (fix at the start value) -> {name: value|None}."""
    fix = {}
    for a in items or []:
        if "=" in a:
            k, v = a.split("=", 1)
            if not k.strip():
                raise UsageError(f"--fix {a!r}: expected name or name=value")
            try:
                fix[k.strip()] = parse_value(v)
            except UsageError as e:
                raise UsageError(f"--fix {a}: {e}") from None
        elif a.strip():
            fix[a.strip()] = None
        else:
            raise UsageError("--fix: empty parameter name")
    return fix


def fix(model, fixed: dict) -> None:
    """Each ``--fix`` name is a fitted parameter of ``model``, each value in its range."""
    from ..core.params import StaticSpec, check_value, param_specs

    specs = param_specs(model.Params)
    for name, value in fixed.items():
        if name not in specs:
            close = difflib.get_close_matches(name, list(specs), n=3, cutoff=0.6)
            hint = f"; did you mean {' or '.join(close)}?" if close else ""
            raise UsageError(f"--fix {name}: {model.name} has no parameter {name!r}; "
                             f"parameters are {', '.join(specs)}{hint}")
        spec = specs[name]
        if isinstance(spec, StaticSpec):
            raise UsageError(f"--fix {name}: a static (configuration) field is not fitted; "
                             f"set it with --param {name}=VALUE instead")
        if value is not None:
            if isinstance(value, (str, bool)):
                raise UsageError(f"--fix {name}={value}: expected a number or a comma list of numbers")
            check_value(f"--fix {name}", value, spec)


# ------------------------------------------------------------------------- angles
def angle_list(option: str, text: str, lo: float = -90.0, hi: float = 90.0) -> np.ndarray:
    """'a:b:step' (inclusive) or a comma list, in degrees, every angle in [lo, hi]."""
    try:
        if ":" in text:
            a, b, s = (float(x) for x in text.split(":"))
            if not s > 0 or not math.isfinite(a + b + s):
                raise ValueError
            arr = np.arange(a, b + 0.5 * s, s)
        else:
            arr = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise UsageError(f"{option} {text}: expected degrees as a comma list (0,30,60) or a range "
                         "start:stop:step with step > 0 (-89:89:1)") from None
    if arr.size == 0 or np.any(~np.isfinite(arr)) or np.any((arr < lo) | (arr > hi)):
        raise UsageError(f"{option} {text}: angles must lie in [{lo:g}, {hi:g}] degrees"
                         + (f", got {arr.min():g}..{arr.max():g}" if arr.size else ", got none"))
    return arr


def max_theta(text: str):
    """``--max-theta``: degrees in (0, 90], or none/off/no (keep every sample)."""
    if text.strip().lower() in ("none", "off", "no"):
        return None
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not 0 < v <= 90:
        raise UsageError(f"--max-theta {text}: must lie in (0, 90] degrees, or 'none'")
    return v
