"""A task's settings as one frozen dataclass, and the command line made from it.

Every setting is a dataclass field declared with :func:`setting`: its default, its help
text, how a command-line value is read, and the flag group it belongs to. From these
fields :func:`build_parser` makes the flags (``policy_iters`` is ``--policy-iters``), so
each setting has one definition and one default. :class:`RunSettings` holds the settings
every task has; a task subclasses it with :func:`task_settings`, adding its own fields
and giving inherited ones other defaults.

:func:`parse_settings` reads a command line into a settings object. Precedence, lowest
first: the fields' defaults, the ``--preset``'s values, the settings saved in
``DIR/progress.json`` with ``--resume DIR``, the flags given on the command line (so only
flags given again change a resumed run). A setting missing from a saved run (one added
after the run was saved) takes its field's default.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
from typing import Any, Callable, Dict, Iterable, Mapping, Optional, Sequence, Type, TypeVar

__all__ = ["setting", "task_settings", "RunSettings", "build_parser", "parse_settings",
           "settings_from_dict", "settings_to_dict", "saved_settings",
           "positive_float", "non_negative_float", "positive_int", "non_negative_int",
           "optional_float"]

S = TypeVar("S", bound="RunSettings")

#: the metadata keys of a :func:`setting` field
_META = "pilco_flag"


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


#: command-line readers of values that must be > 0, >= 0, an integer >= 1 or >= 0
positive_float = _number(float, lambda v: v > 0, "positive")
non_negative_float = _number(float, lambda v: v >= 0, "zero or positive")
positive_int = _number(int, lambda v: v >= 1, "at least 1")
non_negative_int = _number(int, lambda v: v >= 0, "at least 0")


def level_name(text: str) -> str:
    """A logging level's name (any case) or number, kept as given; ValueError otherwise."""
    from ..runtime import log_level

    log_level(text)
    return text


def optional_float(text: str) -> Optional[float]:
    """A number, or ``None``/``none`` for "not set"."""
    if text.strip().lower() == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or None, got {text!r}") from None


def setting(default: Any, help: str, *, kind: Optional[Callable[[str], Any]] = None,
            choices: Optional[Sequence[Any]] = None, nargs: Any = None,
            metavar: Any = None, group: str = "task", negatable: bool = False,
            flag: bool = True, unset: Optional[str] = None) -> Any:
    """A settings field: ``default`` and the flag's ``help``.

    ``kind`` reads a command-line value (default: the type of ``default``; a bool is a
    switch that sets True, or with ``negatable`` also has a ``--no-`` form); ``choices``,
    ``nargs`` and ``metavar`` as in :meth:`argparse.ArgumentParser.add_argument` (a value
    with ``nargs`` is kept as a tuple); ``group``: the help section; ``flag=False``: a
    setting the task derives itself, with no flag; ``unset``: what a default of None
    means, shown in ``--help`` as the default (without it a None default is not shown)."""
    meta = dict(help=help, kind=kind, choices=choices, nargs=nargs, metavar=metavar,
                group=group, negatable=negatable, flag=flag, unset=unset)
    return dataclasses.field(default=default, metadata={_META: meta})


def task_settings(**defaults: Any) -> Callable[[type], type]:
    """Class decorator making a frozen settings dataclass; ``defaults`` give inherited
    fields new defaults (their help and reading stay the base's)."""

    def wrap(cls: type) -> type:
        inherited = {f.name: f for base in cls.__mro__[1:] if dataclasses.is_dataclass(base)
                     for f in dataclasses.fields(base)}
        unknown = sorted(set(defaults) - set(inherited))
        if unknown:
            raise TypeError(f"{cls.__name__}: no inherited settings {unknown} to give a "
                            f"default")
        annotations = dict(cls.__dict__.get("__annotations__", {}))
        for name, value in defaults.items():
            annotations[name] = inherited[name].type
            setattr(cls, name, dataclasses.field(default=value,
                                                 metadata=inherited[name].metadata))
        cls.__annotations__ = annotations
        return dataclasses.dataclass(frozen=True)(cls)

    return wrap


@task_settings()
class RunSettings:
    """The settings every task has: the run, the loop and the optimisers."""

    # -- the run
    seed: int = setting(0, "random seed", kind=non_negative_int, group="experiment")
    episodes: Optional[int] = setting(4, "total episodes including the random ones",
                                      kind=positive_int, group="experiment")
    random_episodes: int = setting(1, "episodes with random actions first",
                                   kind=non_negative_int, group="experiment")
    horizon: int = setting(50, "steps per episode and planning horizon", kind=positive_int,
                           group="experiment")
    output: str = setting("runs/run-seed{seed}", "run directory ({seed} is replaced)",
                          group="experiment")
    resume: Optional[str] = setting(None, "continue the run saved in DIR with its next "
                                    "episode", kind=str, metavar="DIR", group="experiment")
    quiet: bool = setting(False, "no progress bars", group="experiment")
    no_render: bool = setting(False, "do not render the last episode", group="experiment")
    no_figures: bool = setting(False, "do not draw figures", group="experiment")
    log_level: str = setting("WARNING", "logging level", kind=level_name, group="experiment")
    preset: Optional[str] = setting(None, "start from a named set of settings; flags given "
                                    "still win", kind=str, group="experiment")
    # -- learning
    basis_functions: int = setting(10, "RBF policy basis functions", kind=positive_int,
                                   group="learning")
    policy_iters: int = setting(50, "optimiser iterations per policy optimisation",
                                kind=positive_int, group="learning")
    policy_restarts: int = setting(1, "policy optimisation restarts", kind=positive_int,
                                   group="learning")
    policy_restart_from: int = setting(
        1, "episode (1-based, random ones counted) from which --policy-restarts apply",
        kind=positive_int, group="learning")
    policy_restart_step: int = setting(
        0, "restarts added in each episode after --policy-restart-from in which restarts "
        "run (with --policy-restart-when unsolved: the longer a run stays unsolved, the "
        "wider its search)", kind=non_negative_int, group="learning")
    policy_patience: int = setting(10, "iterations for --policy-min-rel-improvement",
                                   kind=positive_int, group="learning")
    policy_iters_first: Optional[int] = setting(
        None, "iterations of the first policy optimisation", kind=positive_int,
        group="learning", unset="as --policy-iters")
    model_iters: int = setting(1000, "L-BFGS iterations of GP training", kind=positive_int,
                               group="learning")
    model_restarts: int = setting(1, "GP training restarts", kind=positive_int,
                                  group="learning")
    max_data: Optional[int] = setting(
        None, "GP learns from the first N transitions only (0: all)",
        kind=non_negative_int, group="learning", unset="all")
    policy_optimizer: str = setting(
        "L-BFGS-B", "policy optimiser (BFGS: dense update, as the MATLAB release)",
        kind=str.upper, choices=("L-BFGS-B", "BFGS"), group="learning")
    policy_compiler: str = setting(
        "graph", "compile the policy objective and its gradient as a TensorFlow graph, or "
        "whole by XLA (faster on small problems; compiled once per data-size bucket and "
        "cached on disk: $PILCO_XLA_CACHE, default ~/.cache/pilco/xla; TensorFlow logs "
        "'Error parsing text-format tensorflow.XlaSerializedCacheEntry' for each program it "
        "loads from there: harmless, the load succeeds)",
        choices=("graph", "xla"), group="learning")
    policy_min_rel_improvement: Optional[float] = setting(
        None, "stop a policy optimisation once its predicted return grew by less than this "
        "fraction of it over the last --policy-patience iterations (0: never)",
        kind=float, group="learning", unset="never")
    policy_early_stop: str = setting(
        "always", "apply --policy-min-rel-improvement always, or only once an episode was "
        "solved", choices=("always", "solved"), group="learning")
    policy_restart_when: str = setting(
        "always", "run the --policy-restarts restarts from random policies in every policy "
        "optimisation, or only until an episode was solved", choices=("always", "unsolved"),
        group="learning")
    policy_warm_start: str = setting(
        "always", "start each policy search from the previous episode's policy always, or "
        "only once an episode was solved (before: from a fresh random policy)",
        choices=("always", "solved"), group="learning")
    policy_start_mixture: Optional[float] = setting(
        None, "split the policy objective's start distribution into 2D+1 narrower Gaussians "
        "of the same mean and covariance, two of them this many standard deviations out "
        "along each principal axis, so that a policy failing from the flanks of the start "
        "distribution is seen to fail (0: off; costs 2D+1 times per evaluation)",
        kind=non_negative_float, group="learning", unset="off")
    policy_start_mixture_when: str = setting(
        "solved", "use --policy-start-mixture in every policy search; only once an episode "
        "was solved (keeping a policy that works); or, once solved, only when the plain "
        "search's policy is fragile (its plain expected return above the mixture's by more "
        "than --policy-fragile-gap)", choices=("always", "solved", "fragile"),
        group="learning")
    policy_fragile_gap: float = setting(
        1.0, "gap between the plain and the start mixture's expected return (in steps at "
        "full cost) above which a policy is fragile", kind=non_negative_float,
        group="learning")
    policy_flank_points: Optional[float] = setting(
        None, "beside the policy objective's start distribution (one moment-matched "
        "Gaussian), roll out the 2D known states this many standard deviations out along "
        "each of its principal axes through the model's mean dynamics and weigh their "
        "return with the Gaussian's, so that a policy failing from the flanks of the start "
        "distribution is seen to fail (0: off)", kind=non_negative_float, group="learning",
        unset="off")
    policy_start_samples: int = setting(
        0, "the same with this many known states drawn from the start distribution (drawn "
        "again in every episode; 0: off)", kind=non_negative_int, group="learning")
    policy_leave_repeat: Optional[float] = setting(
        None, "while no episode was solved, in an episode whose policy search runs "
        "restarts: when the search continued from the last policy wins but is predicted to "
        "return within this much of what the last episode really did (a failure the model "
        "already knows), run the best of the fresh searches instead (0: off; returns "
        "summed over the horizon)", kind=non_negative_float, group="learning", unset="off")
    policy_start_scale: Optional[float] = setting(
        None, "beside the policy objective's start distribution, propagate one this many "
        "times as wide (its standard deviations) and average their expected returns, so "
        "that the objective sees the flanks of the start distribution with the model's "
        "uncertainty there (0: off; twice the cost per evaluation)",
        kind=non_negative_float, group="learning", unset="off")
    policy_start_points_when: str = setting(
        "solved", "use --policy-flank-points, --policy-start-samples and "
        "--policy-start-scale in every policy search, or only once an episode was solved",
        choices=("always", "solved"), group="learning")
    model_min_rel_improvement: Optional[float] = setting(
        None, "stop GP training once its loss fell by less than this fraction of it over "
        "the last 10 iterations (0: never)", kind=float, group="learning", unset="never")
    retrain_unchanged_model: bool = setting(
        False, "train the GPs again even if their training data did not change",
        group="learning")


def _meta(field: dataclasses.Field) -> Dict[str, Any]:
    return field.metadata.get(_META, {})


def _flag_fields(cls: type) -> Iterable[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if _meta(f).get("flag", False)]


def build_parser(cls: Type[RunSettings], description: str = "",
                 presets: Optional[Mapping[str, Mapping[str, Any]]] = None,
                 prog: Optional[str] = None,
                 examples: Sequence[str] = ()) -> argparse.ArgumentParser:
    """The flags of the settings class ``cls``, one per field, grouped as declared. A flag
    left out of the command line is absent from the parsed namespace (defaults are
    applied by :func:`parse_settings`, which knows presets and saved runs); ``--help``
    shows each field's default as ``(default X)`` (:func:`_default_text`) and, under
    ``examples:``, each of ``examples`` (flags) after the command's name."""
    presets = dict(presets or {})
    epilog = ("examples:\n" + "\n".join(f"  %(prog)s {e}" for e in examples)
              if examples else None)
    parser = argparse.ArgumentParser(prog=prog, description=description, epilog=epilog,
                                     argument_default=argparse.SUPPRESS,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    groups: Dict[str, Any] = {}
    for field in _flag_fields(cls):
        meta = _meta(field)
        group = groups.get(meta["group"])
        if group is None:
            group = groups[meta["group"]] = parser.add_argument_group(meta["group"])
        name = "--" + field.name.replace("_", "-")
        text = meta["help"] + _default_text(field.default, meta)
        if field.name == "preset":
            if not presets:
                continue
            group.add_argument(name, dest=field.name, choices=sorted(presets), help=(
                text + "; " + "; ".join(f"{k}: {_describe(v)}" for k, v in presets.items())))
            continue
        kwargs: Dict[str, Any] = dict(dest=field.name, help=text)
        if isinstance(field.default, bool) and meta["kind"] is None:
            kwargs["action"] = (argparse.BooleanOptionalAction if meta["negatable"]
                                else "store_true")
        else:
            kwargs["type"] = meta["kind"] or type(field.default)
            for key in ("choices", "nargs", "metavar"):
                if meta[key] is not None:
                    kwargs[key] = tuple(meta[key]) if key == "metavar" and isinstance(
                        meta[key], list) else meta[key]
        group.add_argument(name, **kwargs)
    return parser


def _default_text(default: Any, meta: Mapping[str, Any]) -> str:
    """`` (default X)`` for a flag's help: a switch's state as on/off when it has a
    ``--no-`` form and nothing for a plain switch (off unless given), a None default as
    the field's ``unset`` text or nothing."""
    if isinstance(default, bool) and meta.get("kind") is None:
        return f" (default {'on' if default else 'off'})" if meta.get("negatable") else ""
    if default is None:
        return f" (default {meta['unset']})" if meta.get("unset") else ""
    return f" (default {_shown(default)})"


def _shown(value: Any) -> str:
    return " ".join(map(str, value)) if isinstance(value, tuple) else str(value)


def _describe(values: Mapping[str, Any]) -> str:
    """A preset's values as flags (a switch as ``--name`` when on, ``--no-name`` off)."""
    def flag(key: str, value: Any) -> str:
        name = key.replace("_", "-")
        if isinstance(value, bool):
            return f"--{name}" if value else f"--no-{name}"
        return f"--{name} {_shown(value)}"

    return " ".join(flag(k, v) for k, v in values.items())


def settings_from_dict(cls: Type[S], values: Mapping[str, Any]) -> S:
    """``cls`` from a mapping such as a saved run's settings: unknown keys are dropped
    (settings since removed), missing ones take their field's default, lists become the
    tuples of fields with several values."""
    kept: Dict[str, Any] = {}
    for field in dataclasses.fields(cls):
        if field.name not in values:
            continue
        value = values[field.name]
        if isinstance(value, list):
            value = tuple(value)
        kept[field.name] = value
    return cls(**kept)


def settings_to_dict(settings: RunSettings) -> Dict[str, Any]:
    """The settings as a JSON-ready dict (tuples as lists)."""
    return {k: list(v) if isinstance(v, tuple) else v
            for k, v in dataclasses.asdict(settings).items()}


def saved_settings(directory: str) -> Dict[str, Any]:
    """The settings saved in ``directory/progress.json`` (runs saved by older versions
    stored them under ``args``); raises FileNotFoundError without that file."""
    with open(os.path.join(directory, "progress.json"), encoding="utf-8") as f:
        progress = json.load(f)
    return dict(progress.get("settings") or progress.get("args") or {})


def parse_settings(cls: Type[S], argv: Optional[Sequence[str]] = None, *,
                   description: str = "",
                   presets: Optional[Mapping[str, Mapping[str, Any]]] = None,
                   prog: Optional[str] = None, examples: Sequence[str] = ()) -> S:
    """The settings of a command line (precedence in the module's docstring); ``output``
    is ``--resume``'s directory on resume, else ``--output`` with ``{seed}`` replaced.
    Bad values exit with argparse's usage error (status 2) naming the flag."""
    presets = {k: dict(v) for k, v in (presets or {}).items()}
    names = {f.name for f in dataclasses.fields(cls)}
    for name, values in presets.items():
        unknown = sorted(set(values) - names)
        if unknown:
            raise ValueError(f"preset {name!r} sets unknown settings {unknown}")
    parser = build_parser(cls, description, presets, prog, examples)
    given = vars(parser.parse_args(argv))
    saved: Dict[str, Any] = {}
    if given.get("resume"):
        try:
            saved = saved_settings(given["resume"])
        except FileNotFoundError:
            parser.error(f"--resume {given['resume']}: no progress.json there")
        except (OSError, ValueError, AttributeError) as err:  # unreadable, not JSON, no dict
            parser.error(f"--resume {given['resume']}: progress.json is not a run's "
                         f"({type(err).__name__}: {err})")
    values: Dict[str, Any] = {}
    preset = given.get("preset") or saved.get("preset")
    if preset:
        if preset not in presets:
            parser.error(f"--preset {preset}: this task has no such preset")
        values.update(presets[preset])
    values.update({k: v for k, v in saved.items() if k in names})
    values.update(given)
    settings = settings_from_dict(cls, values)
    output = (settings.resume if settings.resume
              else settings.output.format(seed=settings.seed))
    return dataclasses.replace(settings, output=output)
