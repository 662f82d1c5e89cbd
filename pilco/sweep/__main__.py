"""``python -m pilco.sweep TASK --seeds 0-19 ...``: see :mod:`pilco.sweep`."""
import sys

from ..runtime import quiet_tensorflow

quiet_tensorflow()  # the sweep's runs inherit TF_CPP_MIN_LOG_LEVEL

from .cli import main  # noqa: E402 - after quiet_tensorflow

if __name__ == "__main__":
    sys.exit(main())
