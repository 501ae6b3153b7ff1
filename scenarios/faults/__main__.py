"""``python -m scenarios.faults``: see ``scenarios.faults.suite``."""

import sys

from scenarios.faults.suite import main

sys.exit(main())
