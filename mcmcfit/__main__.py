"""``python -m mcmcfit`` is the ``mcmcfit`` command."""

import sys

from mcmcfit.cli import main

sys.exit(main())
