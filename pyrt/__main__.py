"""``python -m pyrt`` runs the ``pyrt`` command."""

import sys

from pyrt.cli import main

sys.exit(main())
