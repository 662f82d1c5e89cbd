"""A task's settings as one frozen dataclass, and the command line made from it.

Every setting is a dataclass field declared with :func:`setting`
(:mod:`pilco.experiment.settings`): its default, its help text, how a command-line value
is read, and the flag group it belongs to. From these fields :func:`build_parser` makes
the flags (``policy_iters`` is ``--policy-iters``), so each setting has one definition,
one default and one check. :class:`RunSettings` holds the settings every task has: the
loop's (:class:`~pilco.experiment.LoopSettings`, which the loop reads under the same
names) and the run's own; a task subclasses it with :func:`task_settings`, adding its
own fields and giving inherited ones other defaults.

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
import os
from typing import Any, Dict, Iterable, Mapping, Optional, Sequence, Type, TypeVar

from ..experiment.config import LoopSettings
from ..experiment.settings import (field_meta, level_name, non_negative_float,
                                   non_negative_int, optional_float, positive_float,
                                   positive_int, probability, setting, task_settings)

__all__ = ["setting", "task_settings", "RunSettings", "SafetySettings", "build_parser",
           "parse_settings", "settings_from_dict", "settings_to_dict", "saved_settings",
           "positive_float", "non_negative_float", "positive_int", "non_negative_int",
           "probability", "optional_float"]

S = TypeVar("S", bound="RunSettings")


@task_settings()
class RunSettings(LoopSettings):
    """The settings every task has: the loop's (:class:`~pilco.experiment.LoopSettings`,
    read by the loop as they are) and the run's own: where it writes, what it shows, the
    policy's size."""

    output: str = setting("runs/run-seed{seed}", "run directory ({seed} is replaced)",
                          group="experiment")
    resume: Optional[str] = setting(None, "continue the run saved in DIR with its next "
                                    "episode", kind=str, metavar="DIR", group="experiment")
    no_render: bool = setting(False, "do not render the last episode", group="experiment")
    no_figures: bool = setting(False, "do not draw figures", group="experiment")
    log_level: str = setting("WARNING", "logging level", kind=level_name, group="experiment")
    preset: Optional[str] = setting(None, "start from a named set of settings; flags given "
                                    "still win", kind=str, group="experiment")
    basis_functions: int = setting(10, "RBF policy basis functions", kind=positive_int,
                                   group="learning")


@task_settings()
class SafetySettings(RunSettings):
    """The settings of a task with Safe PILCO's loop (:mod:`pilco.experiment.safety`):
    the risk threshold, the risk's starting weight, the searches per episode and how the
    steps' probabilities combine."""

    risk_threshold: float = setting(0.1, "largest predicted probability of breaking the "
                                    "constraint over the horizon for a policy to run",
                                    kind=probability, group="safety")
    mu: float = setting(50.0, "starting weight of the risk in the policy objective (return "
                        "minus mu times the risk)", kind=positive_float, group="safety")
    safe_attempts: int = setting(3, "policy searches per episode before giving up on a safe "
                                 "policy (mu x1.5 after each unsafe one)", kind=positive_int,
                                 group="safety")
    safe_first_search: str = setting(
        "penalised", "each episode's first policy search: on the return minus mu times the "
        "risk (Safe PILCO's), or 'plain', on the return alone, mu weighing the risk only in "
        "the searches after a policy predicted above the threshold",
        choices=("penalised", "plain"), group="safety")
    risk_rule: str = setting("independent", "how the steps' probabilities combine: "
                             "'independent' (1 - prod(1 - p_t), Safe PILCO's) or 'union' "
                             "(sum, a bound)", choices=("independent", "union"),
                             group="safety")

    def safety(self, constraint, safe_action):
        """The :class:`~pilco.experiment.safety.Safety` of these settings for
        ``constraint``, running ``safe_action`` (a constant action [U] or a controller
        ``x -> u``) when no policy is predicted safe."""
        from ..experiment.safety import Safety

        if not callable(safe_action):
            safe_action = list(safe_action)
        return Safety(constraint, self.risk_threshold, safe_action,
                      attempts=self.safe_attempts, rule=self.risk_rule,
                      first_search=self.safe_first_search)


def _flag_fields(cls: type) -> Iterable[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if field_meta(f).get("flag", False)]


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
        meta = field_meta(field)
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
    tuples of fields with several values, and a single value of such a field (a preset's,
    or a run saved before the setting took several) a tuple of one."""
    kept: Dict[str, Any] = {}
    for field in dataclasses.fields(cls):
        if field.name not in values:
            continue
        value = values[field.name]
        if isinstance(value, list):
            value = tuple(value)
        elif (value is not None and not isinstance(value, tuple)
              and (field_meta(field) or {}).get("nargs") is not None):
            value = (value,)
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


def _today(renamed: Mapping[Any, Any], value: Any) -> Any:
    """A saved setting's value under today's name for it (``renamed``: earlier value ->
    today's, from the settings class's ``EARLIER_VALUES``)."""
    try:
        return renamed.get(value, value)
    except TypeError:  # a list or another unhashable value: never renamed
        return value


def parse_settings(cls: Type[S], argv: Optional[Sequence[str]] = None, *,
                   description: str = "",
                   presets: Optional[Mapping[str, Mapping[str, Any]]] = None,
                   prog: Optional[str] = None, examples: Sequence[str] = (),
                   exit_on_error: bool = True) -> S:
    """The settings of a command line (precedence in the module's docstring); ``output``
    is ``--resume``'s directory on resume, else ``--output`` with ``{seed}`` replaced.
    Bad values, and values the settings' checks refuse together, exit with argparse's
    usage error (status 2) naming the setting; with ``exit_on_error=False`` they raise
    ``ValueError`` with the same message instead (nothing printed)."""
    presets = {k: dict(v) for k, v in (presets or {}).items()}
    names = {f.name for f in dataclasses.fields(cls)}
    for name, values in presets.items():
        unknown = sorted(set(values) - names)
        if unknown:
            raise ValueError(f"preset {name!r} sets unknown settings {unknown}")
    parser = build_parser(cls, description, presets, prog, examples)
    if not exit_on_error:
        def refuse(message: str):
            raise ValueError(message)

        def leave(status: int = 0, message: Optional[str] = None):  # --help, --version
            raise ValueError(message or f"the command line ends the program ({status})")

        parser.error, parser.exit = refuse, leave  # this parser is ours alone
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
    earlier = getattr(cls, "EARLIER_VALUES", {})
    values.update({k: _today(earlier.get(k, {}), v) for k, v in saved.items() if k in names})
    values.update(given)
    try:
        settings = settings_from_dict(cls, values)
    except ValueError as err:  # a check across settings (LoopSettings and the task's)
        parser.error(str(err))
    output = (settings.resume if settings.resume
              else settings.output.format(seed=settings.seed))
    return dataclasses.replace(settings, output=output)
