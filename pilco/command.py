"""The ``pilco`` command (also ``python -m pilco``): one entry point for the tasks, the
seed sweep and the diagnosis of a run.

==================================  ================================================
command                             the same as
==================================  ================================================
``pilco run TASK [task flags]``     ``python -m pilco.tasks TASK [task flags]``
``pilco sweep TASK [sweep flags]``  ``python -m pilco.sweep TASK [sweep flags]``
``pilco diagnose RUN_DIR [flags]``  ``python -m pilco.diagnose RUN_DIR [flags]``
``pilco tasks``                     the task names, one a line
==================================  ================================================

``pilco COMMAND --help`` shows a command's flags (``pilco run TASK --help`` the task's),
``pilco --version`` the installed package's version. Every usage line and help says
``pilco ...``, also when a command runs as ``python -m pilco.tasks`` and the like.
Each command's modules are imported only when it runs, and TensorFlow's start-up is
quieted (:func:`pilco.runtime.quiet_tensorflow`) before any of them is.
"""
from __future__ import annotations

import sys
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from .runtime import quiet_tensorflow

__all__ = ["COMMANDS", "EXAMPLES", "main", "version"]

PROG = "pilco"


def version() -> str:
    """The package's version: its installed metadata's, else (pilco run from a checkout
    that is not installed) :data:`pilco.__version__`."""
    from importlib import metadata

    try:
        return metadata.version("pilco")
    except metadata.PackageNotFoundError:
        from . import __version__

        return __version__


def _task_names() -> List[str]:
    from .tasks import TASKS

    return list(TASKS)


def _pick(argv: List[str], choices: Sequence[str], usage: str, prog: str,
          what: str) -> Optional[int]:
    """The exit status when ``argv`` does not start with one of ``choices``: 0 after
    printing ``usage`` for ``-h``/``--help``, 2 after a usage error naming the missing or
    unknown ``what``; None when it does."""
    if argv and argv[0] in ("-h", "--help"):
        sys.stdout.write(usage)
        return 0
    if not argv or argv[0] not in choices:
        problem = f"no {what} given" if not argv else f"unknown {what} {argv[0]!r}"
        sys.stderr.write(f"{usage.splitlines()[0]}\n{prog}: error: {problem}; choose one "
                         f"of {', '.join(choices)} (see {prog} --help)\n")
        return 2
    return None


def _run(argv: List[str]) -> int:
    names = _task_names()
    usage = (f"usage: {PROG} run TASK [task flags]\n"
             f"       {PROG} run TASK --help   (the task's flags)\n"
             f"tasks: {', '.join(names)}, or package.module:ATTRIBUTE (a task of your own)\n")
    from .tasks import get_task, is_task_reference

    if not (argv and is_task_reference(argv[0])):  # a task of the user's: get_task checks it
        status = _pick(argv, names, usage, f"{PROG} run", "task")
        if status is not None:
            return status

    try:
        task = get_task(argv[0])
    except (ValueError, TypeError) as err:  # a module:ATTRIBUTE that is not a task
        sys.stderr.write(f"{usage.splitlines()[0]}\n{PROG} run: error: {err}\n")
        return 2
    return task.main(argv[1:])


def _sweep(argv: List[str]) -> int:
    from .sweep.cli import main

    return main(argv, prog=f"{PROG} sweep")


def _diagnose(argv: List[str]) -> int:
    from .diagnose import main

    return main(argv)


def _tasks(argv: List[str]) -> int:
    if argv and argv[0] in ("-h", "--help"):
        sys.stdout.write(f"usage: {PROG} tasks\n\nThe names of the tasks that "
                         f"`{PROG} run` and `{PROG} sweep` take, one a line.\n")
        return 0
    if argv:
        sys.stderr.write(f"usage: {PROG} tasks\n{PROG} tasks: error: unexpected "
                         f"argument(s): {' '.join(argv)}\n")
        return 2
    for name in _task_names():
        print(name)
    return 0


#: command -> (its function ``(argv) -> exit status``, its arguments, what it does)
COMMANDS: Dict[str, Tuple[Callable[[List[str]], int], str, str]] = {
    "run": (_run, "TASK [task flags]", "run one task (its flags: pilco run TASK --help)"),
    "sweep": (_sweep, "TASK [sweep flags]",
              "run a task for many seeds and settings on Ray; success rates"),
    "diagnose": (_diagnose, "RUN_DIR [flags]",
                 "why did a run fail: model, optimiser or objective"),
    "tasks": (_tasks, "", "list the task names"),
}


#: the examples of ``pilco --help`` (each runs: tests/test_command.py)
EXAMPLES = ("tasks", "run cartpole --seed 3", "sweep cartpole --seeds 0-19",
            "diagnose runs/cartpole-seed3 --episode 4")


def usage() -> str:
    """The ``pilco --help`` text."""
    width = max(len(f"{name} {args}".strip()) for name, (_, args, _) in COMMANDS.items())
    lines = [f"usage: {PROG} COMMAND [arguments]", "",
             "PILCO: probabilistic inference for learning control.", "", "commands:"]
    lines += [f"  {f'{name} {args}'.strip():<{width}}  {text}"
              for name, (_, args, text) in COMMANDS.items()]
    lines += ["", "options:", "  -h, --help     show this help message and exit",
              "  -V, --version  show the package's version and exit", "",
              f"`{PROG} COMMAND --help` shows a command's flags.", "", "examples:"]
    lines += [f"  {PROG} {example}" for example in EXAMPLES]
    return "\n".join(lines) + "\n"


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run ``pilco COMMAND ...`` (``argv`` without the program name, default
    ``sys.argv[1:]``); returns the command's exit status, 2 for a missing or unknown
    command; ``--version`` prints the package's version."""
    quiet_tensorflow()
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in ("-V", "--version"):
        print(f"{PROG} {version()}")
        return 0
    status = _pick(argv, list(COMMANDS), usage(), PROG, "command")
    if status is not None:
        return status
    command, _, _ = COMMANDS[argv[0]]
    return command(argv[1:])


if __name__ == "__main__":
    sys.exit(main())
