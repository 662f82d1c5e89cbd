"""``python -m pilco.sweep TASK --seeds 0-19 ...``: see :mod:`pilco.sweep`."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
