"""``python -m aero_rig.cli``: the ``aero-rig`` command."""

import sys

from . import main

sys.exit(main())
