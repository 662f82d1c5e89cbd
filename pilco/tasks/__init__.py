"""The paper's experiments as library code, each a :class:`~pilco.tasks.base.Task`: a
frozen settings dataclass (:mod:`pilco.tasks.settings`) and the builders of its run.

======================  =============================================================
task                    where
======================  =============================================================
``cartpole``            :mod:`pilco.tasks.cartpole`, the MATLAB release's swing-up
``reacher``             :mod:`pilco.tasks.reacher`, the 7-DoF Fetch arm
``damaged_reacher``     :mod:`pilco.tasks.reacher`, the arm with its elbow stuck
``adaptation``          :mod:`pilco.tasks.adaptation`, damage in the middle of a run
``pendulum``            :mod:`pilco.tasks.pendulum`, the reference port's Pendulum-v1
``reacher_multi``       :mod:`pilco.tasks.reacher_multi`, one policy for any target
======================  =============================================================

:data:`TASKS` is the one registry: ``python -m pilco.tasks``, the seed sweep
(:mod:`pilco.sweep`) and the diagnosis (:mod:`pilco.diagnose`) look tasks up here.
``python -m pilco.tasks TASK [flags]`` runs a task exactly as ``examples/TASK.py
[flags]`` does (the seed sweep starts every run that way).
"""
from __future__ import annotations

import importlib
from typing import Callable, Optional, Sequence

__all__ = ["TASKS", "get_task", "build_parser", "task_main", "run_task", "open_run"]

#: task name -> ``"module:attribute"`` of its :class:`~pilco.tasks.base.Task` under
#: :mod:`pilco.tasks` (imported when first asked for: the command line stays quick)
TASKS = {
    "cartpole": "cartpole:CARTPOLE",
    "reacher": "reacher:REACHER",
    "damaged_reacher": "reacher:DAMAGED_REACHER",
    "adaptation": "adaptation:ADAPTATION",
    "pendulum": "pendulum:PENDULUM",
    "reacher_multi": "reacher_multi:REACHER_MULTI",
}


def get_task(name: str):
    """The :class:`~pilco.tasks.base.Task` registered as ``name``; ValueError naming the
    known tasks otherwise."""
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; choose one of {', '.join(TASKS)}")
    module, attribute = TASKS[name].split(":")
    return getattr(importlib.import_module(f"{__name__}.{module}"), attribute)


def build_parser(name: str):
    """The argument parser of task ``name`` (its flags and defaults)."""
    return get_task(name).parser()


def task_main(name: str) -> Callable[[Optional[Sequence[str]]], int]:
    """The ``main(argv) -> exit status`` of task ``name``."""
    return get_task(name).main


def run_task(name: str, argv: Optional[Sequence[str]] = None) -> int:
    """Run task ``name`` with command-line flags ``argv``; returns its exit status."""
    return get_task(name).main(argv)


def open_run(directory: str):
    """The run saved in ``directory`` as a resumed :class:`~pilco.experiment.Experiment`
    through its task (quiet, not rendering), so that its agent builder can replay the
    learning of an earlier episode; a run of a task not registered here is reopened from
    its saved agent alone."""
    import logging

    from ..experiment import Experiment, ExperimentConfig, RunStore

    progress = RunStore(directory).load_progress()
    task = progress["config"]["task"]
    if task in TASKS:
        return get_task(task).reopen(directory)
    logging.getLogger(__name__).info(
        "task %r is not reopened through its task: the saved agent is used", task)
    return Experiment.resume(directory, ExperimentConfig(**progress["config"]),
                             build_agent=None)
