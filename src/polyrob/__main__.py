"""``python -m polyrob``: the ``polyrob`` command."""

import sys

from polyrob.cli import main

sys.exit(main())
