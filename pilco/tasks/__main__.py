"""``python -m pilco.tasks TASK [flags]``: run one of the paper's experiments."""
from __future__ import annotations

import sys

from ..runtime import quiet_tensorflow

# TensorFlow's C++ log lines drown the progress output; pilco logs through `logging`.
quiet_tensorflow()


def main(argv=None) -> int:
    from . import TASKS, run_task

    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in TASKS:
        print(f"usage: python -m pilco.tasks {{{','.join(TASKS)}}} [flags]\n"
              f"       python -m pilco.tasks TASK --help   (the task's flags)",
              file=sys.stderr if argv and argv[0] not in ("-h", "--help") else sys.stdout)
        return 0 if argv and argv[0] in ("-h", "--help") else 2
    return run_task(argv[0], argv[1:])


if __name__ == "__main__":
    sys.exit(main())
