"""``python -m robocell``: the ``robocell`` command."""

import sys

from .cli.main import main

# Guarded: a process started with multiprocessing's "spawn" (the daemon's recorder) imports the
# parent's main module again, and must not run the command a second time.
if __name__ == "__main__":
    sys.exit(main())
