"""``python -m bayesplate.cli``: the ``bayesplate`` command."""

import sys

from .main import main

sys.exit(main())
