"""``python -m imubench``: the same command line as the ``imubench`` script."""

import sys

try:
    from imubench.cli import main
except KeyboardInterrupt:  # Ctrl-C while the modules load: nothing started, no traceback
    sys.exit(130)

sys.exit(main())
