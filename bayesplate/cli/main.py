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
import threading

from . import batch, cases, diagnose, estimate, import_case, modes, report, sample

__all__ = ["INTERRUPTED", "main", "build_parser"]

#: Exit status after Ctrl-C (SIGINT): 128 + 2, as shells report it.
INTERRUPTED = 130

#: Signals taken as Ctrl-C (issue 39): what batch systems (Slurm, systemd, Docker, CI
#: runners) and a closed terminal send. The exit status is 128 + the signal's number, as
#: shells report a death by it: 143 after SIGTERM, 129 after SIGHUP.
STOP_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name)
)

_stopped_by = None  # the first of STOP_SIGNALS received by this run of main()

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


def _stop_signal(signum, frame):
    """SIGTERM or SIGHUP: what Ctrl-C does at this moment, the signal noted for the status.

    The handler of SIGINT in place is called: Python's raises ``KeyboardInterrupt``; the
    sampler's takes it at the end of the step under way (emcee would print a traceback for
    an exception raised inside it). Where SIGINT is ignored (a background job of a
    non-interactive shell), ``KeyboardInterrupt`` is raised here. A second one is ignored:
    the first one's cleanup (children ended, a cluster closed) runs to its end.
    """
    global _stopped_by
    if _stopped_by is not None:
        return
    _stopped_by = signum
    handler = signal.getsignal(signal.SIGINT)
    if callable(handler):
        handler(signal.SIGINT, frame)
    else:
        raise KeyboardInterrupt


def _catch_stop_signals():
    """Install :func:`_stop_signal` for :data:`STOP_SIGNALS`; the handlers it replaced.

    Only in the main thread (where Python runs signal handlers); none where SIGHUP was
    ignored on purpose (``nohup``).
    """
    global _stopped_by
    _stopped_by = None
    if threading.current_thread() is not threading.main_thread():
        return {}
    saved = {}
    for signum in STOP_SIGNALS:
        if signum != signal.SIGTERM and signal.getsignal(signum) == signal.SIG_IGN:
            continue  # nohup: the user asked for hangups to be ignored
        saved[signum] = signal.signal(signum, _stop_signal)
    return saved


def _children_now():
    """The multiprocessing children of this process now (none when it never loaded the module)."""
    if "multiprocessing" not in sys.modules:
        return set()
    return set(sys.modules["multiprocessing"].active_children())


def _end_children(before, exiting=False):
    """End every child started during the command (forked workers, a local cluster's).

    With `exiting` (``os._exit`` follows), also what multiprocessing's exit handler does:
    its finalizers give the semaphores back to its resource tracker, which otherwise warns
    on standard error of leaked ones after the command's last line.
    """
    if "multiprocessing" in sys.modules:
        import multiprocessing.util

        from ..parallel import end_children

        end_children(keep=before)
        if exiting:
            multiprocessing.util._exit_function()


def main(argv=None):
    """Run the command line; returns the exit status.

    Ctrl-C (SIGINT), SIGTERM and SIGHUP stop any command the same way: one line on standard
    error, every step finished kept (files are written whole or not at all), the children
    ended, and the exit status 130 (SIGINT), 143 (SIGTERM) or 129 (SIGHUP): 128 + the
    signal's number, as shells report a death by the signal.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s"
    )
    saved = _catch_stop_signals()
    before = _children_now()
    from ..io import CaseError  # after parsing: --help and usage errors need no numerics

    try:
        status = args.func(args)
        if argv is None:
            # the work is done and every file is closed: a Ctrl-C (or SIGTERM, SIGHUP) from
            # here on (during the interpreter's shutdown) would only turn the command's own
            # status into a death by the signal, so it is ignored; one arriving before this
            # line is caught below
            for signum in (signal.SIGINT, *saved):
                signal.signal(signum, signal.SIG_IGN)
            saved = {}
        return status
    except CaseError as err:
        print(f"bayesplate: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # Ctrl-C, SIGTERM, SIGHUP: one line, the shell's status for the signal; every file
        # is written whole (temporary name, then rename) and caches and chains keep what
        # was done
        signum = _stopped_by or signal.SIGINT
        by = "" if signum == signal.SIGINT else f" ({signal.Signals(signum).name})"
        print(
            f"bayesplate {args.command}: interrupted{by}; run it again to resume", file=sys.stderr
        )
        _end_children(before, exiting=argv is None)
        status = INTERRUPTED if signum == signal.SIGINT else 128 + signum
        if argv is None:  # the command itself: end here, so that the status stays as said
            # (once in about 15 test runs the interpreter's shutdown after a Ctrl-C reported
            # death by SIGINT instead; the output files are all closed by now)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(status)
        return status
    except BrokenPipeError:
        # standard output closed early (`bayesplate diagnose ... | head`): one line, no
        # traceback; what was stored stays stored. Nothing more can reach the pipe: for the
        # command itself, point it at /dev/null so that the interpreter's last flush stays
        # quiet too (a caller of main(argv) keeps its own standard output)
        if argv is None:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        print(f"bayesplate {args.command}: standard output closed; stopped", file=sys.stderr)
        return 1
    finally:
        _end_children(before)  # every other way out (an error's traceback)
        for signum, handler in saved.items():  # a caller in-process gets its own back
            signal.signal(signum, handler)


if __name__ == "__main__":
    sys.exit(main())
