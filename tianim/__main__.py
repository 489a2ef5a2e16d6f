"""``python -m tianim`` is the ``tianim`` command."""

import sys

from tianim.cli import main

sys.exit(main())
