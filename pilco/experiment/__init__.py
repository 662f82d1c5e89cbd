"""Running PILCO experiments: episodes, the learning loop, the run directory, the
command line shared by the tasks.

=================  ==============================================================
module             job
=================  ==============================================================
``episode``        :class:`Episode`, :func:`rollout`, :func:`make_env`, the env contract
``settings``       :func:`setting` fields, settings classes declared once
``config``         :class:`LoopSettings`, :class:`ExperimentConfig`, the settings of a run
``hooks``          :class:`RunHooks`, what a task tells the loop (one object)
``loop``           :class:`Experiment`, the paper's Algorithm 1 with saving/resume
``learning``       the model and policy phases of a learned episode, predictions
``scoring``        saturating cost, the solved rule, per-episode records
``store``          :class:`RunStore`, the files of a run directory
``signals``        SIGTERM as a stop at the next safe point
``progress``       progress bars and the optimisers' callback
``report``         the timing and episode tables
=================  ==============================================================

This package logs through :mod:`logging`; nothing here prints (the tasks print their tables).
"""
from .config import ExperimentConfig, LoopSettings
from .episode import (DISTANCE_KEYS, EnvironmentContractError, Episode, make_env, rollout,
                      stack_transitions)
from .hooks import FunctionHooks, RunHooks
from .loop import Experiment
from .scoring import PHASES, episode_solved, saturating_cost
from .store import RunStore

__all__ = ["DISTANCE_KEYS", "EnvironmentContractError", "Episode", "Experiment",
           "ExperimentConfig", "FunctionHooks", "LoopSettings", "PHASES", "RunHooks",
           "RunStore", "episode_solved", "make_env", "rollout", "saturating_cost",
           "stack_transitions"]
