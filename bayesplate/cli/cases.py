"""``bayesplate cases``: list the bundled case files."""

from __future__ import annotations

__all__ = ["register"]


def run(args):
    """List the bundled cases with their paths."""
    from ..io import bundled_case_names, bundled_case_path

    for name in bundled_case_names():
        print(f"{name:20s} {bundled_case_path(name)}")
    return 0


def register(sub):
    """Add the ``cases`` subcommand."""
    p = sub.add_parser("cases", help="list the bundled case files")
    p.set_defaults(func=run)
