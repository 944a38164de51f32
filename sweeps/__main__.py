"""``python -m sweeps`` is ``coman-sweep``."""

import sys

from sweeps.cli import main

sys.exit(main())
