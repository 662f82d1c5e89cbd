"""The paper's experiments as library code: each task builds its environment, agent and
run settings from command-line flags, runs, and reports.

======================  =============================================================
task                    module
======================  =============================================================
``cartpole``            :mod:`pilco.tasks.cartpole`, the MATLAB release's swing-up
``reacher``             :mod:`pilco.tasks.reacher`, the 7-DoF Fetch arm
``damaged_reacher``     :mod:`pilco.tasks.reacher` with ``damaged=True``
``adaptation``          :mod:`pilco.tasks.adaptation`, damage in the middle of a run
``pendulum``            :mod:`pilco.tasks.pendulum`, the reference port's Pendulum-v1
======================  =============================================================

``python -m pilco.tasks TASK [flags]`` runs a task exactly as ``examples/TASK.py
[flags]`` does (the seed-sweep tool starts every run that way); ``pendulum`` runs the
workload of ``examples/pendulum.py``, a script in the paper code's style, with the
experiment loop (its run directory, summary, resume and figures).
"""
from __future__ import annotations

import importlib
from typing import Callable, Optional, Sequence

__all__ = ["TASKS", "task_main", "run_task", "build_parser"]

#: task name -> (module under pilco.tasks, keyword arguments of its ``main``)
TASKS = {
    "cartpole": ("cartpole", {}),
    "reacher": ("reacher", {}),
    "damaged_reacher": ("reacher", {"damaged": True}),
    "adaptation": ("adaptation", {}),
    "pendulum": ("pendulum", {}),
}


def task_main(name: str) -> Callable[[Optional[Sequence[str]]], int]:
    """The ``main(argv) -> exit status`` of task ``name``."""
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; choose one of {', '.join(TASKS)}")
    module, kwargs = TASKS[name]
    main = importlib.import_module(f"{__name__}.{module}").main
    return lambda argv=None: main(argv, **kwargs)


def run_task(name: str, argv: Optional[Sequence[str]] = None) -> int:
    """Run task ``name`` with command-line flags ``argv``; returns its exit status."""
    return task_main(name)(argv)


def build_parser(name: str):
    """The argument parser of task ``name`` (its flags and defaults)."""
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; choose one of {', '.join(TASKS)}")
    module, kwargs = TASKS[name]
    build = importlib.import_module(f"{__name__}.{module}").build_parser
    return build(**kwargs)
