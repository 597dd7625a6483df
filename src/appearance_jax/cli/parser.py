"""The argument parser of ``appearance-jax``: top-level help, ``--version`` and one subparser per
command module.

A command module (``models_cmd``, ``eval_cmd``, ``fit_cmd``, ``demo_cmd``, ``bubble_cmd`` here, or a
module of another package with the same interface) provides ``add_parser(subparsers)``, which adds its
subparser and sets ``fn=run`` as its default, and ``run(args) -> int`` (the exit code); it may
raise ``ValueError`` for bad input (exit 2, one error line). To add a command, import its module
here and append it to :data:`COMMANDS`.
"""

from __future__ import annotations

import argparse

from ..export import cli as export_cmd
from . import bubble_cmd, demo_cmd, eval_cmd, fit_cmd, models_cmd
from .checks import EXIT_CODES

#: the command modules, in the order of the help text
COMMANDS = [models_cmd, eval_cmd, fit_cmd, export_cmd, demo_cmd, bubble_cmd]

DESCRIPTION = """\
appearance-jax: differentiable BSDF models and a fitting pipeline for measured reflectance.

Commands: models (parameter tables), eval (a BSDF on an in-plane grid or at a
table's directions), fit (a BSDF to a table, with a report), export (a fit's
params.json as a Mitsuba 3 BSDF), demo, bubble-sim (soap-film flow on a
bubble, Huang 2022 Ch. 3: thickness maps and rendered frames). Angles are in
degrees on the command line; in-plane tables use a signed theta_o (theta_o =
theta_i is the mirror direction, -theta_i retro-reflection). A TABLE is a .csv
file (appearance-jax table v1), a MERL .binary file or proxy:NAME[:GRID] (a
Neural-BRDF proxy of a MERL material; GRID gonio, in_plane or merl)."""

EPILOG = """\
examples:
  appearance-jax models rough_plastic
  appearance-jax fit data/tables/merl-proxy-red-fabric-in-plane.csv --model rough_plastic \\
      --loss cos_log --out out/fit

exit status:
""" + "\n".join(f"  {code}  {what}" for code, what in EXIT_CODES.items()) + """

appearance-jax COMMAND -h shows a command's options; docs/cli.md has them all."""


def version() -> str:
    """The installed distribution's version, else the package's ``__version__``."""
    from importlib import metadata

    try:
        return metadata.version("appearance-jax")
    except metadata.PackageNotFoundError:
        from .. import __version__

        return __version__


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="appearance-jax", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"%(prog)s {version()}",
                   help="print the version and exit")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="COMMAND")
    for module in COMMANDS:
        module.add_parser(sub)
    for command in sub.choices.values():
        command.add_argument("--no-compile-cache", action="store_true",
                             help="do not read or write the on-disk cache of compiled programs (default: on, in "
                                  "$APPEARANCE_JAX_COMPILE_CACHE or ~/.cache/appearance-jax/xla; "
                                  "APPEARANCE_JAX_COMPILE_CACHE=off also turns it off)")
    sub.help = "one of: " + ", ".join(sub.choices)
    return p
