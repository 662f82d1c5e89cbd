"""The command line shared by the tasks: common flags, ``--resume``, logging, and the
one shared end of every task's ``main`` (tables, figures, exit status)."""
from __future__ import annotations

import argparse
import json
import math
import os
from typing import Any, Callable, Dict, List, Optional, Sequence

from ..runtime import configure_logging, configure_threads
from .loop import Experiment
from .report import format_episode_table, format_timing_table

__all__ = ["add_common_arguments", "add_preset_argument", "learning_settings",
           "parse_args_with_resume", "parse_task_args", "open_experiment",
           "positive_float", "non_negative_float", "positive_int", "non_negative_int",
           "configure_logging", "configure_threads", "finish"]


def add_common_arguments(parser: argparse.ArgumentParser, *, episodes: int, steps: int,
                         basis_functions: int, policy_iters: int, model_iters: int,
                         policy_restarts: int = 1, model_restarts: int = 1,
                         policy_method: str = "L-BFGS-B",
                         policy_min_rel_improvement: Optional[float] = None,
                         policy_patience: int = 10,
                         model_min_rel_improvement: Optional[float] = None,
                         policy_early_stop: str = "always",
                         policy_restart_when: str = "always", policy_restart_from: int = 1,
                         policy_warm_start: str = "always",
                         max_data: Optional[int] = None, random_episodes: int = 1,
                         output: str = "runs/run-seed{seed}") -> None:
    """Flags shared by the tasks (defaults given per task)."""
    g = parser.add_argument_group("experiment")
    for name, kind, default, text in (
            ("--seed", non_negative_int, 0, "random seed"),
            ("--episodes", positive_int, episodes, "total episodes including the random ones"),
            ("--random-episodes", non_negative_int, random_episodes,
             "episodes with random actions first"),
            ("--horizon", positive_int, steps, "steps per episode and planning horizon")):
        g.add_argument(name, type=kind, default=default, help=f"{text} (default %(default)s)")
    g.add_argument("--output", default=output,
                   help="run directory (default %(default)s; {seed} is replaced)")
    g.add_argument("--resume", metavar="DIR", default=None,
                   help="continue the run saved in DIR with its next episode")
    for name, text in (("--quiet", "no progress bars"),
                       ("--no-render", "do not render the last episode"),
                       ("--no-figures", "do not draw figures")):
        g.add_argument(name, action="store_true", help=text)
    g.add_argument("--log-level", default="WARNING", help="logging level (default %(default)s)")
    g = parser.add_argument_group("learning")
    for name, kind, default, text in (
            ("--basis-functions", positive_int, basis_functions, "RBF policy basis functions"),
            ("--policy-iters", positive_int, policy_iters,
             "optimiser iterations per policy optimisation"),
            ("--policy-restarts", positive_int, policy_restarts, "policy optimisation restarts"),
            ("--policy-restart-from", positive_int, policy_restart_from,
             "episode (1-based, random ones counted) from which --policy-restarts apply"),
            ("--policy-patience", positive_int, policy_patience,
             "iterations for --policy-min-rel-improvement"),
            ("--policy-iters-first", positive_int, None,
             "iterations of the first policy optimisation (None: --policy-iters)"),
            ("--model-iters", positive_int, model_iters, "L-BFGS iterations of GP training"),
            ("--model-restarts", positive_int, model_restarts, "GP training restarts"),
            ("--max-data", non_negative_int, max_data,
             "GP learns from the first N transitions only (0 or None: all)")):
        g.add_argument(name, type=kind, default=default, help=f"{text} (default %(default)s)")
    g.add_argument("--policy-optimizer", choices=("L-BFGS-B", "BFGS"), type=str.upper,
                   default=policy_method,
                   help="policy optimiser (BFGS: dense update, as the MATLAB release; "
                        "default %(default)s)")
    g.add_argument("--policy-min-rel-improvement", type=float, default=policy_min_rel_improvement,
                   help="stop a policy optimisation once its predicted return grew by less "
                        "than this fraction of it over the last --policy-patience iterations "
                        "(default %(default)s; 0 or None: never)")
    # switches that change once the run has solved an episode
    for name, choices, default, text in (
            ("--policy-early-stop", ("always", "solved"), policy_early_stop,
             "apply --policy-min-rel-improvement always, or only once an episode was solved"),
            ("--policy-restart-when", ("always", "unsolved"), policy_restart_when,
             "run the --policy-restarts restarts from random policies in every policy "
             "optimisation, or only until an episode was solved"),
            ("--policy-warm-start", ("always", "solved"), policy_warm_start,
             "start each policy search from the previous episode's policy always, or only "
             "once an episode was solved (before: from a fresh random policy)")):
        g.add_argument(name, choices=choices, default=default,
                       help=f"{text} (default %(default)s)")
    g.add_argument("--model-min-rel-improvement", type=float, default=model_min_rel_improvement,
                   help="stop GP training once its loss fell by less than this fraction of "
                        "it over the last 10 iterations (default %(default)s; 0 or None: never)")
    g.add_argument("--retrain-unchanged-model", action="store_true",
                   help="train the GPs again even if their training data did not change")


def learning_settings(args: argparse.Namespace) -> Dict[str, Any]:
    """The :class:`ExperimentConfig` fields set by :func:`add_common_arguments`' learning
    flags, as keyword arguments."""
    return dict(
        max_data=args.max_data, model_iters=args.model_iters,
        model_restarts=args.model_restarts,
        model_min_rel_improvement=args.model_min_rel_improvement,
        retrain_unchanged_model=args.retrain_unchanged_model,
        policy_iters=args.policy_iters, policy_restarts=args.policy_restarts,
        policy_method=args.policy_optimizer,
        policy_min_rel_improvement=args.policy_min_rel_improvement,
        policy_patience=args.policy_patience, policy_early_stop=args.policy_early_stop,
        policy_restart_when=args.policy_restart_when,
        policy_restart_from=args.policy_restart_from,
        policy_warm_start=args.policy_warm_start,
        policy_iters_first=args.policy_iters_first,
    )


def add_preset_argument(parser: argparse.ArgumentParser,
                        presets: Dict[str, Dict[str, Any]]) -> None:
    """``--preset NAME``: a named set of defaults (``{flag dest: value}``); flags given
    on the command line still win. Unknown keys in a preset are a programming error."""
    known = {a.dest for a in parser._actions}  # noqa: SLF001 - argparse has no API
    for name, values in presets.items():
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"preset {name!r} sets unknown flags {unknown}")
    parser.add_argument("--preset", choices=sorted(presets), default=None,
                        help="start from a named set of settings; flags given still win: "
                             + "; ".join(f"{k}: {_describe(v)}" for k, v in presets.items()))
    parser.set_defaults(_presets=presets)


def _describe(values: Dict[str, Any]) -> str:
    return " ".join(f"--{k.replace('_', '-')} {v}" for k, v in values.items())


def parse_args_with_resume(parser: argparse.ArgumentParser,
                           argv: Optional[Sequence[str]] = None,
                           added_later: Optional[Dict[str, Any]] = None) -> argparse.Namespace:
    """Parse ``argv``. Precedence, lowest first: the task's defaults, ``--preset``'s
    values, the settings saved in ``DIR/progress.json`` with ``--resume DIR``, the flags
    given (so only flags given again, e.g. ``--episodes``, change a resumed run).
    ``added_later``: settings the task gained after runs were saved, each with the value
    that reproduces a run saved without it (a resumed run missing one gets that value,
    not today's default)."""
    args = parser.parse_args(argv)
    presets = getattr(args, "_presets", {})
    saved: Dict[str, Any] = {}
    if args.resume:
        path = os.path.join(args.resume, "progress.json")
        if not os.path.exists(path):
            parser.error(f"--resume {args.resume}: no progress.json there")
        with open(path, encoding="utf-8") as f:
            saved = json.load(f).get("args", {})
        if saved:
            saved = {**(added_later or {}), **saved}
    preset = args.preset if getattr(args, "preset", None) else saved.get("preset")
    if preset or saved:
        known = {a.dest for a in parser._actions}  # noqa: SLF001 - argparse has no API
        parser.set_defaults(**presets.get(preset, {}))
        parser.set_defaults(**{k: v for k, v in saved.items() if k in known})
        args = parser.parse_args(argv)
    if hasattr(args, "_presets"):
        del args._presets
    if args.resume:
        args.output = args.resume
    else:
        args.output = args.output.format(seed=args.seed)
    return args


def _number(kind: type, test: Callable[[float], bool], what: str) -> Callable[[str], Any]:
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            noun = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {noun}, got {text!r}") from None
        if not (math.isfinite(value) and test(value)):
            raise argparse.ArgumentTypeError(f"must be {what} and finite, got {text}")
        return value

    parse.__name__ = what.replace(" ", "_")
    return parse


#: argparse ``type=`` of flags that must be > 0, >= 0, an integer >= 1 or >= 0
positive_float = _number(float, lambda v: v > 0, "positive")
non_negative_float = _number(float, lambda v: v >= 0, "zero or positive")
positive_int = _number(int, lambda v: v >= 1, "at least 1")
non_negative_int = _number(int, lambda v: v >= 0, "at least 0")


def parse_task_args(parser: argparse.ArgumentParser,
                    argv: Optional[Sequence[str]] = None,
                    added_later: Optional[Dict[str, Any]] = None) -> argparse.Namespace:
    """A task's flags (:func:`parse_args_with_resume`), with logging set up at their
    ``--log-level``."""
    args = parse_args_with_resume(parser, argv, added_later)
    configure_logging(args.log_level)
    configure_threads()
    return args


def open_experiment(args: argparse.Namespace, config, build, **kwargs):
    """A new :class:`~pilco.experiment.Experiment` of ``config`` in ``args.output``, or
    the one saved there when ``args.resume`` is set; ``kwargs`` go to either."""
    kwargs.setdefault("args", vars(args))
    if args.resume:
        return Experiment.resume(args.output, config, build, **kwargs)
    return Experiment(config, args.output, build, **kwargs)


def finish(exp, summary: Dict[str, Any], args: argparse.Namespace, title: str,
           reference: Optional[Dict[str, float]] = None,
           figures: Optional[Callable[[], List[str]]] = None,
           notes: Sequence[str] = ()) -> int:
    """Print the episode and timing tables (and ``notes``), draw ``figures()`` unless
    ``--no-figures``, close the env; returns the exit status: 130 after an interrupt
    (with how to resume), else 0. The one shared end of every task's ``main``."""
    print(format_episode_table(summary))
    for note in notes:
        print(note)
    print()
    print(format_timing_table(summary["seconds"], title=title, reference=reference))
    try:
        if exp.interrupted:
            print(f"\nInterrupted: agent and data saved in {exp.directory}; continue with "
                  f"--resume {exp.directory}")
            return 130
        if figures is not None and not args.no_figures:
            paths = figures()
            print(f"\nFigures: {', '.join(os.path.basename(p) for p in paths)}")
        print(f"Solved: {summary['solved']} (episode {summary['solved_at_episode']}); "
              f"success: {summary['success']}; results in {exp.directory}")
        return 0
    finally:
        exp.close()
