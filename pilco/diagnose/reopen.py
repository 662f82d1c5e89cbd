"""Reopen a saved run directory as a resumed :class:`~pilco.experiment.Experiment`, the
input of :func:`pilco.diagnose.diagnose`: through its task when the task is registered
(:func:`pilco.tasks.open_run`), so that the experiment has the task's agent builder
(needed to replay the learning of an earlier episode) and its replay hook; else with its
saved agent alone, which is enough for the last episode.
"""
from __future__ import annotations

from ..tasks import open_run

__all__ = ["open_run"]
