"""The ``appearance-jax`` command line (reference: docs/cli.md).

:func:`main` parses the arguments (:mod:`.parser`), runs the command and turns a bad option or
input into one ``appearance-jax COMMAND: error: ...`` line on stderr and the exit code
:data:`~.checks.EXIT_USAGE`; other exit codes in :data:`~.checks.EXIT_CODES`. The commands
live in one module each (``models_cmd``, ``eval_cmd``, ``fit_cmd``, ``demo_cmd``), the
option checks in :mod:`.checks`, the physically known parameters held fixed by ``fit`` in
:mod:`.known`.
"""

from __future__ import annotations

import atexit
import os
import sys

from .checks import EXIT_CODES, EXIT_FAILURE, EXIT_NOT_CONVERGED, EXIT_OK, EXIT_USAGE
from .parser import build_parser

__all__ = ["main", "console", "build_parser", "EXIT_CODES", "EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_NOT_CONVERGED"]


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


def console() -> None:
    """The ``appearance-jax`` console script: :func:`main`, then the process exits with its code.

    The exit skips the interpreter's teardown (freeing every module, XLA client and compiled
    program object one by one): ~0.5 s of a 5 s warm ``fit`` on 2 cores. Everything the command
    wrote is closed by then; output buffers are flushed and the ``atexit`` handlers (JAX's,
    logging's, matplotlib's) run as on a normal exit. An exception, ``-h`` or an argparse error
    leaves the usual way.
    """
    code = main()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can be written anyway
            pass
    os._exit(int(code))


def _compile_cache(args) -> None:
    """The on-disk cache of compiled programs: on unless ``--no-compile-cache`` (or the
    environment, :mod:`appearance_jax.core.compile_cache`) turns it off."""
    from ..core import compile_cache

    if getattr(args, "no_compile_cache", False):
        compile_cache.disable()
    else:
        compile_cache.ensure()
