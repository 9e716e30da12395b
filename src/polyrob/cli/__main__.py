"""``python -m polyrob.cli``: the ``polyrob`` command."""

import sys

from polyrob.cli import console

sys.exit(console())
