"""The ``polyrob`` command: a thin layer over the library's functions.

The CLI parses, calls :mod:`polyrob.pipeline` and the stage modules, and
prints: every command prints a text report or, with ``--json``, one JSON
document.  Every user error (a :class:`~polyrob.errors.PolyrobError`, or a
bad option value) ends as one line on stderr and exit status 2; Ctrl-C ends
with status 130.  Output files are written to a temporary file and renamed,
and output paths are checked before the work starts, so a failed or
interrupted run leaves no file.  Only :mod:`argparse` and the standard
library are imported here: each command imports what it needs when it runs,
so ``polyrob --help`` is fast.
"""

from __future__ import annotations

import argparse
import functools
import sys

from polyrob.cli.options import parse_joint_values
from polyrob.errors import PolyrobError

__all__ = ["main", "build_parser", "parse_joint_values"]


class PolyrobParser(argparse.ArgumentParser):
    """argparse with its errors on one line (``polyrob: error: argument --mc: ...``), exit 2."""

    def error(self, message):
        self.exit(2, f"polyrob: error: {message} (see `{self.prog} --help`)\n")


def build_parser() -> argparse.ArgumentParser:
    from polyrob.cli import analyze, batch, bounds, files, listing, run, synth
    from polyrob.cli.common import HelpFormatter

    parser = PolyrobParser(
        prog="polyrob",
        description="Robust controllers with a mathematical guarantee for serial robots described in URDF.",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=PolyrobParser)
    sub.add_parser = functools.partial(sub.add_parser, formatter_class=HelpFormatter)
    for module in (listing, bounds, analyze, synth, run, files, batch):
        module.register(sub)
    return parser


def _run(args, guard) -> int:
    from polyrob.progress import stop_current

    try:
        return int(args.func(args) or 0)
    except PolyrobError as exc:
        if guard.interrupted.is_set():
            raise KeyboardInterrupt from None
        print(f"polyrob: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `polyrob robots | head`: not an error
        sys.stderr.close()
        return 0
    finally:
        stop_current()  # the job's progress line ends with the command


def _caused_by_interrupt(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt is in the exception's cause/context chain."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def main(argv=None) -> int:
    """Run the ``polyrob`` command with ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    from polyrob.cli.interrupt import EXIT_INTERRUPTED, InterruptGuard, interrupted_line

    guard = InterruptGuard()
    try:
        with guard:
            args = build_parser().parse_args(argv)
            from polyrob.provenance import command_line

            with command_line(sys.argv[1:] if argv is None else argv, args):  # what written files record
                return _run(args, guard)
    except KeyboardInterrupt:
        pass
    except Exception as exc:
        # an error raised while the interrupt tore down workers is part of the interrupt, and so
        # is one a KeyboardInterrupt turned into (a C extension's import: "initialization failed"),
        # which may reach here before the watchdog thread has flagged the interrupt
        if not (guard.interrupted.is_set() or _caused_by_interrupt(exc)):
            raise
    print(interrupted_line(), file=sys.stderr, flush=True)
    return EXIT_INTERRUPTED


def console() -> int:
    """The ``polyrob`` console script: :func:`main`, and after an interrupt an exit without finalization.

    A SIGINT can land inside a C extension's import (pinocchio, BLAS
    threads): the interrupted line is printed and the files are cleaned up,
    but finalizing the half-imported interpreter can then abort ("Fatal
    Python error: PyThreadState_Get", status -6 instead of 130, one
    ``.ci/run`` in four on a loaded machine).  So the process ends at once,
    its streams flushed and its children stopped; in-process callers of
    :func:`main` get the status back.
    """
    from polyrob.cli.interrupt import EXIT_INTERRUPTED, stop_children

    code = main()
    if code == EXIT_INTERRUPTED:
        import os

        stop_children()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(console())
