"""``python -m bayesplate.cli``: the ``bayesplate`` command."""

import sys

try:
    from .main import main
except KeyboardInterrupt:  # Ctrl-C while the command line is still being imported
    print("bayesplate: interrupted", file=sys.stderr)
    sys.exit(130)

sys.exit(main())
