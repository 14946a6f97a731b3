"""The ``bayesplate`` command: the parser and the entry point.

Every subcommand takes a case file (see ``bayesplate cases`` for the bundled ones); output is
a human-readable table by default and JSON with ``--json FILE`` (``-`` for standard output).
Units: frequencies in Hz, moduli in GPa, lengths in mm.

Each subcommand is one module of :mod:`bayesplate.cli` with ``register(subparsers)`` and
``run(args)``; heavy imports (the estimators' runs, sampling, plots, the report) happen
inside ``run``, so ``bayesplate --help`` stays fast.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys

from . import batch, cases, diagnose, estimate, import_case, modes, report, sample

__all__ = ["INTERRUPTED", "main", "build_parser"]

#: Exit status after Ctrl-C (SIGINT): 128 + 2, as shells report it.
INTERRUPTED = 130

#: The subcommands' modules, in the order of ``bayesplate --help``.
_COMMANDS = (cases, modes, import_case, diagnose, estimate, report, sample, batch)


class _Parser(argparse.ArgumentParser):
    """argparse's parser with one-line usage errors: ``prog: error: message (see --help)``."""

    def error(self, message):
        """Print one line naming the command and the rule; exit with status 2."""
        line = " ".join(f"{self.prog}: error: {message} (see {self.prog} --help)".split())
        self.exit(2, line + "\n")

    def _get_values(self, action, arg_strings):
        # Python 3.11's argparse drops a "--" given as an option's value (``--tol=--``) and
        # hands the option an empty list, bypassing its type: refuse it instead.
        if action.option_strings and "--" in arg_strings:
            self.error(f"argument {'/'.join(action.option_strings)}: '--' is not a value")
        return super()._get_values(action, arg_strings)


def build_parser():
    """The argument parser of the ``bayesplate`` command."""
    parser = _Parser(
        prog="bayesplate",
        description="Elastic constants of laminated plates from natural frequencies. "
        "Start with `bayesplate cases` (bundled test cases), then "
        "`bayesplate report frederiksen_t300 --quick` (everything about one case in a folder).",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in _COMMANDS:
        command.register(sub)
    return parser


def main(argv=None):
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s"
    )
    from ..io import CaseError  # after parsing: --help and usage errors need no numerics

    try:
        status = args.func(args)
        if argv is None:
            # the work is done and every file is closed: a Ctrl-C from here on (during the
            # interpreter's shutdown) would only turn the command's own status into a death
            # by SIGINT, so it is ignored; one arriving before this line is caught below
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        return status
    except CaseError as err:
        print(f"bayesplate: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # Ctrl-C: one line, the shell's status for SIGINT; every file is written whole
        # (temporary name, then rename) and caches and chains keep what was done
        print(f"bayesplate {args.command}: interrupted; run it again to resume", file=sys.stderr)
        if argv is None:  # the command itself: end here, so that the status stays 130
            # (once in about 15 test runs the interpreter's shutdown after a Ctrl-C reported
            # death by SIGINT instead; the output files are all closed by now)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(INTERRUPTED)
        return INTERRUPTED
    except BrokenPipeError:
        # standard output closed early (`bayesplate diagnose ... | head`): one line, no
        # traceback; what was stored stays stored. Nothing more can reach the pipe: for the
        # command itself, point it at /dev/null so that the interpreter's last flush stays
        # quiet too (a caller of main(argv) keeps its own standard output)
        if argv is None:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        print(f"bayesplate {args.command}: standard output closed; stopped", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
