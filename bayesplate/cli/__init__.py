"""The ``bayesplate`` command line: one module per subcommand, the parser in :mod:`.main`.

The console script ``bayesplate = "bayesplate.cli:main"`` calls :func:`main`.
"""

from .main import build_parser, main

__all__ = ["main", "build_parser"]
