"""``python -m aero_rig.view``: run the view node."""

from .node import main

raise SystemExit(main())
