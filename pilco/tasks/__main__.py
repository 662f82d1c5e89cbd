"""``python -m pilco.tasks TASK [flags]``: run one of the paper's experiments, the same
as ``pilco run TASK [flags]`` (:mod:`pilco.command`, whose usage lines it shows)."""
from __future__ import annotations

import sys

from ..runtime import quiet_tensorflow

# TensorFlow's C++ log lines drown the progress output; pilco logs through `logging`.
quiet_tensorflow()


def main(argv=None) -> int:
    from ..command import COMMANDS

    run, _, _ = COMMANDS["run"]
    return run(list(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    sys.exit(main())
