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
``gym``                 :mod:`pilco.tasks.gym`, any gymnasium environment by its id
``cars``                :mod:`pilco.tasks.cars`, Safe PILCO's two cars at a crossing
======================  =============================================================

:data:`TASKS` is the registry of the package's tasks: ``python -m pilco.tasks``, the seed
sweep (:mod:`pilco.sweep`) and the diagnosis (:mod:`pilco.diagnose`) look tasks up here.
``python -m pilco.tasks TASK [flags]`` runs a task exactly as ``examples/TASK.py
[flags]`` does (the seed sweep starts every run that way).

A task defined outside the package is named ``package.module:ATTRIBUTE``, the module-level
:class:`~pilco.tasks.base.Task` instance (:func:`get_task`): ``pilco run mymod:TASK``,
``pilco sweep mymod:TASK`` and ``pilco diagnose`` of its runs find it as they find the
package's own, the module imported from the working directory or ``PYTHONPATH``.
"""
from __future__ import annotations

import importlib
import os
import sys
from typing import Callable, Optional, Sequence

__all__ = ["TASKS", "get_task", "is_task_reference", "task_import_root", "build_parser",
           "task_main", "run_task", "open_run"]

#: task name -> ``"module:attribute"`` of its :class:`~pilco.tasks.base.Task` under
#: :mod:`pilco.tasks` (imported when first asked for: the command line stays quick)
TASKS = {
    "cartpole": "cartpole:CARTPOLE",
    "reacher": "reacher:REACHER",
    "damaged_reacher": "reacher:DAMAGED_REACHER",
    "adaptation": "adaptation:ADAPTATION",
    "pendulum": "pendulum:PENDULUM",
    "reacher_multi": "reacher_multi:REACHER_MULTI",
    "gym": "gym:GYM",
    "cars": "cars:CARS",
}


def is_task_reference(name: str) -> bool:
    """True when ``name`` names a task by ``module:ATTRIBUTE`` rather than by its registered
    name."""
    return ":" in name


def get_task(name: str):
    """The :class:`~pilco.tasks.base.Task` registered as ``name``, or the one at
    ``package.module:ATTRIBUTE`` (the module imported with the working directory on the
    path, as ``python -m`` has it); ValueError naming the known tasks or the part of the
    reference that failed, TypeError when the attribute is not a task."""
    if name in TASKS:
        module, attribute = TASKS[name].split(":")
        return getattr(importlib.import_module(f"{__name__}.{module}"), attribute)
    if not is_task_reference(name):
        raise ValueError(f"unknown task {name!r}; choose one of {', '.join(TASKS)}, or name "
                         f"a task of your own as package.module:ATTRIBUTE")
    return _import_task(name)


def _import_task(reference: str):
    from .base import Task

    module, _, attribute = reference.partition(":")
    if not module or not attribute.isidentifier() or \
            not all(part.isidentifier() for part in module.split(".")):
        raise ValueError(f"task {reference!r}: expected package.module:ATTRIBUTE")
    if os.getcwd() not in sys.path and "" not in sys.path:
        sys.path.insert(0, os.getcwd())  # `pilco run` as `python -m` would: modules here
    try:
        found = importlib.import_module(module)
    except ImportError as err:
        raise ValueError(f"task {reference!r}: cannot import {module!r} ({err}); is it in "
                         f"the working directory or on PYTHONPATH?") from err
    if not hasattr(found, attribute):
        raise ValueError(f"task {reference!r}: module {module!r} has no attribute "
                         f"{attribute!r}")
    task = getattr(found, attribute)
    if not isinstance(task, Task):
        raise TypeError(f"task {reference!r} is a {type(task).__name__}, not an instance of "
                        f"pilco.tasks.base.Task")
    task.imported_as = reference
    return task


def task_import_root(name: str) -> Optional[str]:
    """The directory a process must have on its path to import the task named ``name``
    (``module:ATTRIBUTE`` only; None for the package's own tasks and for modules that
    are not files): what the seed sweep adds to its runs' ``PYTHONPATH``."""
    if not is_task_reference(name):
        return None
    get_task(name)
    module_name = name.partition(":")[0]
    path = getattr(sys.modules[module_name], "__file__", None)
    if not path:
        return None
    root = os.path.dirname(os.path.abspath(path))
    depth = module_name.count(".") + (os.path.basename(path) == "__init__.py")
    for _ in range(depth):
        root = os.path.dirname(root)
    return root


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
    learning of an earlier episode; a run of a task that cannot be found (a task run from
    a script of its own, a ``module:ATTRIBUTE`` no longer importable) is reopened from its
    saved agent alone."""
    import logging

    from ..experiment import Experiment, ExperimentConfig, RunHooks, RunStore

    progress = RunStore(directory).load_progress()
    task = progress["config"]["task"]
    try:
        found = get_task(task)
    except (ValueError, TypeError) as err:
        # a reference that no longer imports is worth a warning; a script's own task is not
        log = logging.getLogger(__name__)
        (log.warning if is_task_reference(task) else log.info)(
            "%s; the run is reopened from its saved agent", err)
        return Experiment.resume(directory, ExperimentConfig.from_saved(progress["config"]),
                                 RunHooks())
    return found.reopen(directory)
