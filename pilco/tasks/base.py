"""The outline every task shares: :class:`Task`.

A task is a settings class (a frozen dataclass, :mod:`pilco.tasks.settings`) and the
builders that turn one settings object into a run: the loop's configuration
(:meth:`Task.config`), the agent (:meth:`Task.agent_builder`), the one object the loop
calls into (:class:`TaskHooks`, a :class:`~pilco.experiment.hooks.RunHooks`), the
figures. The settings are handed down as one typed object;
nothing below reads the command line. :meth:`Task.main` is the whole command::

    settings = task.parse(argv)         # flags, --preset, --resume (nothing else)
    exp = task.experiment(settings)     # logging, threads; the new run, or the saved one
    summary = task.run(exp, settings)   # the paper's Algorithm 1 (or the task's loop)
    return task.finish(exp, summary, settings)  # tables, figures, exit status
"""
from __future__ import annotations

import dataclasses
import logging
import os
import sys
from typing import Any, Callable, ClassVar, Dict, List, Mapping, Optional, Sequence, Type

from ..experiment import (EnvironmentContractError, Experiment, ExperimentConfig,
                          LoopSettings, RunHooks)
from ..experiment.report import format_episode_table, format_timing_table
from ..experiment.scoring import solved_in_last_episode
from .settings import RunSettings, build_parser, parse_settings, settings_to_dict

__all__ = ["Task", "TaskHooks", "LastEpisodeHooks", "RunDirectoryError"]

logger = logging.getLogger(__name__)


class RunDirectoryError(ValueError):
    """A run directory to resume or reopen whose files are missing, damaged or not a
    run's."""


class TaskHooks(RunHooks):
    """The hooks of a task's run (:class:`~pilco.experiment.hooks.RunHooks`): the env the
    task made (:meth:`Task.make_env`, before the agent, whose builder may need it), the
    agent of :meth:`Task.agent_builder`, the task's settings and loop configuration as
    :attr:`settings` and :attr:`config`. A task with more to say subclasses it and names
    the subclass as its :attr:`Task.run_hooks`."""

    def __init__(self, task: "Task", settings: RunSettings, config: ExperimentConfig, env):
        self.settings, self.config, self.env = settings, config, env
        self._build = task.agent_builder(settings, env)

    def make_env(self, run):
        return self.env

    def build_agent(self, data, start_states):
        return self._build(data, start_states)


class LastEpisodeHooks(TaskHooks):
    """Success: the task is still solved in the run's last episode
    (:func:`~pilco.experiment.scoring.solved_in_last_episode`)."""

    def success(self, summary: Dict[str, Any]) -> bool:
        return solved_in_last_episode(self.config)(summary)


class Task:
    """One of the paper's experiments, built from a settings object.

    Subclasses set :attr:`name`, :attr:`settings`, :attr:`description` (and
    :attr:`presets`, :attr:`paper_seconds`), and define :meth:`config` and
    :meth:`agent_builder`, and name their :class:`TaskHooks` subclass as
    :attr:`run_hooks` when the loop needs more of them (the success rule, the episode
    schedule, what happens between the phases); the other methods have defaults that run
    the loop of :class:`~pilco.experiment.Experiment`.
    """

    #: the task's name (the summary's ``task``, the sweep's and the registry's key)
    name: ClassVar[str] = ""
    #: the task's settings class
    settings: ClassVar[Type[RunSettings]] = RunSettings
    #: one line for ``--help``
    description: ClassVar[str] = ""
    #: named sets of settings (``--preset NAME``): ``{name: {setting: value}}``
    presets: ClassVar[Mapping[str, Mapping[str, Any]]] = {}
    #: the paper's timings of the task, shown beside the run's (``{phase: seconds}``)
    paper_seconds: ClassVar[Optional[Dict[str, float]]] = None
    #: ``module:ATTRIBUTE`` when :func:`pilco.tasks.get_task` imported this instance so
    #: (set on the instance; None for a task found by name or made in code)
    imported_as: Optional[str] = None

    # -- settings -------------------------------------------------------------------------
    def parser(self):
        """The task's :class:`argparse.ArgumentParser` (its flags and defaults)."""
        return build_parser(self.settings, self.description, self.presets, self.prog,
                            self.examples)

    @property
    def reference(self) -> str:
        """How another process finds this task: ``module:ATTRIBUTE`` when it was looked
        up so (:func:`pilco.tasks.get_task`), else :attr:`name` (the package's tasks are
        registered by name, :data:`pilco.tasks.TASKS`). Runs record it as their ``task``,
        so that a sweep starts and the diagnosis reopens a task defined outside the
        package."""
        return self.imported_as or self.name

    @property
    def prog(self) -> str:
        """The task's command in usage lines and errors (``python -m pilco.tasks TASK``
        and ``examples/TASK.py`` run the same)."""
        return f"pilco run {self.reference}"

    @property
    def examples(self) -> List[str]:
        """The flags of the examples in ``--help`` (each runs: tests/test_command.py): a
        seed, continuing that run for more episodes, each preset."""
        defaults = {f.name: f.default for f in dataclasses.fields(self.settings)}
        resume = f"--resume {defaults['output'].format(seed=3)}"
        if defaults["episodes"] is not None:
            resume += f" --episodes {defaults['episodes'] + 2}"
        return ["--seed 3", resume, *[f"--seed 3 --preset {name}" for name in self.presets]]

    def parse(self, argv: Optional[Sequence[str]] = None) -> RunSettings:
        """The settings of command line ``argv`` (``--resume`` restores the saved ones,
        :func:`~pilco.tasks.settings.parse_settings`), checked by :meth:`check`. A usage
        error prints the usage and exits (status 2), as ``--help`` does; nothing else
        happens here (the process's set-up is :meth:`set_up`, done by
        :meth:`experiment`)."""
        try:  # --help and argparse's own usage errors exit inside; the checks raise
            return self.read_settings(argv, exit_on_error=True)
        except ValueError as err:
            self.parser().error(str(err))

    @staticmethod
    def set_up(settings: RunSettings) -> None:
        """The process's set-up for a run of ``settings``: logging at ``--log-level``,
        TensorFlow's threads (:func:`pilco.runtime.configure_threads`) and, with
        ``--policy-compiler xla``, XLA's compilation cache. :meth:`experiment` calls it
        before anything runs on TensorFlow."""
        from ..runtime import configure_logging, configure_threads, use_xla_cache

        configure_logging(settings.log_level)
        configure_threads()
        if settings.policy_compiler == "xla":
            use_xla_cache()

    def read_settings(self, argv: Optional[Sequence[str]] = None, *,
                      exit_on_error: bool = False) -> RunSettings:
        """The settings of command line ``argv`` as :meth:`parse` reads them, checked by
        :meth:`check`, without printing or exiting: ``ValueError`` with the usage error's message
        (``exit_on_error=True``: argparse's own errors and ``--help`` print and exit as on
        the command line). A sweep checks each of its settings so before it starts a run."""
        settings = parse_settings(self.settings, argv, description=self.description,
                                  presets=self.presets, prog=self.prog,
                                  examples=self.examples, exit_on_error=exit_on_error)
        return self.check(settings)

    def check(self, settings: RunSettings) -> RunSettings:
        """Settings derived from others and checks across settings: returns the settings
        to run with, or raises ValueError naming the conflict (a usage error)."""
        return settings

    # -- building a run -------------------------------------------------------------------
    def config(self, settings: RunSettings) -> ExperimentConfig:
        """The loop's :class:`~pilco.experiment.ExperimentConfig`."""
        raise NotImplementedError

    def agent_builder(self, settings: RunSettings, env) -> Callable[..., Any]:
        """``(data, start_states) -> PILCO`` for the run's ``env``."""
        raise NotImplementedError

    def loop_config(self, settings: RunSettings, **task: Any) -> ExperimentConfig:
        """:class:`~pilco.experiment.ExperimentConfig` of the settings: the loop's
        (:class:`~pilco.experiment.LoopSettings`, as they are), the run's reference
        (:attr:`reference`), what it renders and predicts (``--no-render``,
        ``--no-figures``) and the task's own fields ``task`` (env id and arguments, cost
        width, the solved rule)."""
        loop = {f.name: getattr(settings, f.name) for f in dataclasses.fields(LoopSettings)}
        return ExperimentConfig(**loop, task=self.reference, render=not settings.no_render,
                                predictions=not settings.no_figures, **task)

    #: False when the task changes its system during a run (the adaptation breaks its arm):
    #: an env made from the settings is then not the system a late episode ran on
    system_from_settings: ClassVar[bool] = True
    #: the class of the run's hooks (:meth:`hooks`)
    run_hooks: ClassVar[Type[TaskHooks]] = TaskHooks

    def make_env(self, settings: RunSettings, config: ExperimentConfig):
        """The run's environment (made before the agent, whose builder may need it)."""
        from ..experiment import make_env

        return make_env(config.env_id, config.env_kwargs,
                        render=config.render and not self.run_hooks.draws_frames)

    def hooks(self, settings: RunSettings, config: ExperimentConfig, env) -> RunHooks:
        """What the loop calls into for a run of these settings on ``env``: an instance
        of :attr:`run_hooks` (:class:`TaskHooks` or the task's subclass of it)."""
        return self.run_hooks(self, settings, config, env)

    def experiment(self, settings: RunSettings) -> Experiment:
        """A new run in ``settings.output``, or the one saved there with ``--resume``
        (after :meth:`set_up`)."""
        self.set_up(settings)
        config = self.config(settings)
        env = self.make_env(settings, config)
        hooks = self.hooks(settings, config, env)
        try:
            return Experiment(config, settings.output, hooks, settings_to_dict(settings),
                              resume=bool(settings.resume))
        except (OSError, ValueError, KeyError) as err:  # missing, damaged, foreign files
            if not settings.resume:
                raise
            env.close()
            raise RunDirectoryError(f"--resume {settings.output}: cannot reopen the run "
                                    f"({type(err).__name__}: {err})") from err

    def reopen(self, directory: str) -> Experiment:
        """The run saved in ``directory`` with its saved settings, quiet and without
        rendering (e.g. for a diagnosis); the caller's log level is kept."""
        level = logging.getLogger().level
        try:
            settings = self.parse(["--resume", directory, "--quiet", "--no-render"])
        finally:
            logging.getLogger().setLevel(level)
        return self.experiment(settings)

    # -- running and reporting ------------------------------------------------------------
    def run(self, exp: Experiment, settings: RunSettings) -> Dict[str, Any]:
        """The run's learning (its schedule is the hooks'); returns the summary."""
        return exp.run()

    def figures(self, exp: Experiment, settings: RunSettings) -> List[str]:
        """Draw the run's figures into its directory; returns their paths."""
        return []

    def notes(self, summary: Dict[str, Any]) -> List[str]:
        """Lines printed after the episode table."""
        return []

    def finish(self, exp: Experiment, summary: Dict[str, Any],
               settings: RunSettings) -> int:
        """Print the episode and timing tables, draw the figures unless ``--no-figures``,
        close the env; returns the exit status: 130 after an interrupt (with how to
        resume), else 0."""
        print(format_episode_table(summary))
        for note in self.notes(summary):
            print(note)
        print()
        title = (f"Timing ({self.name}, seed {settings.seed}, "
                 f"{len(summary['episodes'])} episodes)")
        print(format_timing_table(summary["seconds"], title=title,
                                  reference=self.paper_seconds))
        try:
            if exp.interrupted:
                print(f"\nInterrupted: agent and data saved in {exp.directory}; continue "
                      f"with --resume {exp.directory}")
                return 130
            if not settings.no_figures:
                paths = self.figures(exp, settings)
                print(f"\nFigures: {', '.join(os.path.basename(p) for p in paths)}")
            print(f"Solved: {summary['solved']} (episode {summary['solved_at_episode']}); "
                  f"success: {summary['success']}; results in {exp.directory}")
            return 0
        finally:
            exp.close()

    def main(self, argv: Optional[Sequence[str]] = None) -> int:
        """The task as a command; returns the exit status (2 after a usage error, such as
        a ``--resume`` directory that holds no run, or an environment that reports no
        task distance, said in one line)."""
        settings = self.parse(argv)
        try:
            exp = self.experiment(settings)
        except RunDirectoryError as err:
            sys.stderr.write(f"{self.prog}: error: {err}\n")
            return 2
        try:
            summary = self.run(exp, settings)
        except EnvironmentContractError as err:  # raised at the first reset
            exp.close()
            sys.stderr.write(f"{self.prog}: error: {err}\n")
            return 2
        return self.finish(exp, summary, settings)
