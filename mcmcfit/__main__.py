"""``python -m mcmcfit`` is the ``mcmcfit`` command.

This module imports only :mod:`mcmcfit.cli`.
"""

import sys

from mcmcfit.cli import main

sys.exit(main())
