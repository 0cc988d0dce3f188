"""``python -m meshcurv``: the same as the ``meshcurv`` command."""

import sys

from .cli import main

sys.exit(main())
