"""``python -m robocell``: the ``robocell`` command."""

import sys

from .main import main

sys.exit(main())
