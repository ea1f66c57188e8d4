"""``python -m reference_runs.femxdem``: see :mod:`reference_runs.femxdem.cli`."""

import sys

from .cli import main

sys.exit(main())
