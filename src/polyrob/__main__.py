"""``python -m polyrob``: the ``polyrob`` command."""

import sys

from polyrob.cli import console

sys.exit(console())
