"""The ``appearance-jax`` command line (reference: docs/cli.md).

:func:`main` parses the arguments (:mod:`.parser`), runs the command and turns a bad option or
input into one ``appearance-jax COMMAND: error: ...`` line on stderr and the exit code
:data:`~.checks.EXIT_USAGE`; other exit codes in :data:`~.checks.EXIT_CODES`. The commands
live in one module each (``models_cmd``, ``eval_cmd``, ``fit_cmd``, ``demo_cmd``), the
option checks in :mod:`.checks`, the physically known parameters held fixed by ``fit`` in
:mod:`.known`.
"""

from __future__ import annotations

import sys

from .checks import EXIT_CODES, EXIT_FAILURE, EXIT_NOT_CONVERGED, EXIT_OK, EXIT_USAGE
from .parser import build_parser

__all__ = ["main", "build_parser", "EXIT_CODES", "EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_NOT_CONVERGED"]


def main(argv: list[str] | None = None) -> int:
    """Run ``appearance-jax`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code
    (argparse's own errors, ``-h`` and ``--version`` raise ``SystemExit`` as usual)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    args._argv = argv
    _compile_cache(args)
    try:
        return args.fn(args)
    except (ValueError, KeyError, FileNotFoundError, IsADirectoryError) as e:
        # bad input: UsageError and TableError are ValueErrors, unknown names KeyErrors
        msg = e.args[0] if isinstance(e, KeyError) and e.args else str(e)  # KeyError's str() adds quotes
        print(f"appearance-jax {args.cmd}: error: {msg}", file=sys.stderr)
        return EXIT_USAGE
    except ArithmeticError as e:
        if type(e).__name__ != "FitDiverged":  # fit.solve.result's; not imported here (jax is slow to import)
            raise
        # the solve ran but ended on non-finite parameters: nothing to report
        print(f"appearance-jax {args.cmd}: error: {e}", file=sys.stderr)
        print(f"status: NOT converged: the solver diverged (exit {EXIT_NOT_CONVERGED})")
        return EXIT_NOT_CONVERGED
    except OSError as e:  # a file that could not be read or written (permissions, disk full)
        print(f"appearance-jax {args.cmd}: error: {e}", file=sys.stderr)
        return EXIT_FAILURE


def _compile_cache(args) -> None:
    """The on-disk cache of compiled programs: on unless ``--no-compile-cache`` (or the
    environment, :mod:`appearance_jax.core.compile_cache`) turns it off."""
    from ..core import compile_cache

    if getattr(args, "no_compile_cache", False):
        compile_cache.disable()
    else:
        compile_cache.ensure()
