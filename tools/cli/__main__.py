"""``python -m tools.cli``: the ``salo`` command."""

import sys

from . import main

sys.exit(main())
