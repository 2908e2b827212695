"""``python -m pyrt`` runs the ``pyrt`` command."""

from pyrt.cli import entry

entry()
