"""Reopen a saved run directory as a resumed :class:`~pilco.experiment.Experiment`, the
input of :func:`pilco.diagnose.diagnose`.

Runs of the tasks ``reacher``, ``damaged_reacher``, ``cartpole``, ``pendulum`` and
``adaptation`` are reopened through their task, so that the experiment has the task's
agent builder (needed to replay the learning of an earlier episode) and, for the
adaptation, its replay hook (:func:`pilco.tasks.adaptation.replay_damage` redoes the
damage's changes to the agent). Other runs are reopened with their saved agent alone, which
is enough for the last episode. The dispatch on the task name is :func:`open_run` alone.
"""
from __future__ import annotations

import importlib
import logging

from ..experiment import Experiment, ExperimentConfig, RunStore

__all__ = ["REOPENABLE", "open_run"]

logger = logging.getLogger(__name__)

#: tasks whose runs can be reopened with their agent builder
REOPENABLE = ("reacher", "damaged_reacher", "cartpole", "pendulum", "adaptation")


def open_run(directory: str):
    """The run saved in ``directory`` as a resumed :class:`~pilco.experiment.Experiment`
    (its episodes, records and settings; the agent builder when the task is known)."""
    progress = RunStore(directory).load_progress()
    task = progress["config"]["task"]
    argv = ["--resume", directory, "--quiet", "--no-render"]
    level = logging.getLogger().level
    try:
        if task in ("reacher", "damaged_reacher"):
            from ..tasks import reacher

            damaged = task == "damaged_reacher"
            return reacher.make_experiment(reacher.parse_args(argv, damaged), task, damaged)
        if task in REOPENABLE:
            module = importlib.import_module(f"..tasks.{task}", __package__)
            return module.make_experiment(module.parse_args(argv))
    finally:
        logging.getLogger().setLevel(level)  # the task's parser sets the run's log level
    logger.info("task %r is not reopened through its task: the saved agent is used", task)
    return Experiment.resume(directory, ExperimentConfig(**progress["config"]),
                             build_agent=None)
