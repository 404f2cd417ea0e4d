"""``python -m nsdrake``: the command line (:mod:`nsdrake.cli`)."""

import sys

from nsdrake.cli import main

sys.exit(main())
