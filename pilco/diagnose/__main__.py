"""``python -m pilco.diagnose RUN_DIR [--episode K] ...``: the command line of
:mod:`pilco.diagnose.cli`."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
