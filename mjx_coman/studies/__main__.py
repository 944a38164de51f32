import sys

from mjx_coman.studies.cli import main

sys.exit(main())
