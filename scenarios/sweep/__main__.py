"""``python -m scenarios.sweep``: see ``scenarios.sweep.study``."""

import sys

from scenarios.sweep.study import main

sys.exit(main())
