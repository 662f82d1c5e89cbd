"""``python -m pilco COMMAND ...``: the ``pilco`` command (:mod:`pilco.command`)."""
import sys

from .command import main

if __name__ == "__main__":
    sys.exit(main())
