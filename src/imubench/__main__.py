"""``python -m imubench``: the same command line as the ``imubench`` script."""

import sys

from imubench.cli import main

sys.exit(main())
