"""``python -m mjx_coman.seed000``."""

import sys

from mjx_coman.seed000.cli import main

sys.exit(main())
