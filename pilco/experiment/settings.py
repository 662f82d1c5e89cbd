"""Settings declared once: :func:`setting` fields and :func:`task_settings` classes.

A setting is a dataclass field declared with :func:`setting`: its default, its help text,
how a command-line value is read, and the flag group it belongs to. A settings class is a
frozen dataclass of such fields made by :func:`task_settings`, which can also give
inherited fields other defaults. The loop's own settings
(:class:`~pilco.experiment.config.LoopSettings`) are one; every task's settings extend
them (:class:`pilco.tasks.settings.RunSettings`), and the command line is made from the
same fields (:func:`pilco.tasks.settings.build_parser`: ``policy_iters`` is
``--policy-iters``), so each setting has one definition, one default and one check.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
from typing import Any, Callable, Dict, Optional, Sequence

__all__ = ["setting", "task_settings", "field_meta", "check_declared", "whole", "positive_float",
           "non_negative_float", "positive_int", "non_negative_int", "probability",
           "optional_float", "level_name"]

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


#: command-line readers of values that must be > 0, >= 0, an integer >= 1 or >= 0, and of a
#: probability strictly between 0 and 1
positive_float = _number(float, lambda v: v > 0, "positive")
non_negative_float = _number(float, lambda v: v >= 0, "zero or positive")
positive_int = _number(int, lambda v: v >= 1, "at least 1")
non_negative_int = _number(int, lambda v: v >= 0, "at least 0")
probability = _number(float, lambda v: 0 < v < 1, "between 0 and 1")


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




def field_meta(field: dataclasses.Field) -> Dict[str, Any]:
    """The command-line metadata of a settings field (empty for a plain field)."""
    return field.metadata.get(_META, {})


def whole(value: Any, minimum: int) -> bool:
    """``value`` is an integer (not a bool) of at least ``minimum``."""
    return not isinstance(value, bool) and isinstance(value, int) and value >= minimum


#: the least value of each whole-number and number kind
_WHOLE = {positive_int: 1, non_negative_int: 0}
_NUMBER = {positive_float: (lambda v: v > 0, "a number > 0"),
           non_negative_float: (lambda v: v >= 0, "a number >= 0"),
           probability: (lambda v: 0 < v < 1, "a number between 0 and 1")}


def check_declared(settings: Any) -> None:
    """Check every :func:`setting` field of ``settings`` against its own declaration, as
    its flag checks a command-line value: a value among its ``choices``, a whole number in
    the range of a ``positive_int``/``non_negative_int`` kind, a finite number in the
    range of a ``positive_float``/``non_negative_float`` kind; ``None`` passes where it is
    the default or where the declaration's ``unset`` says what it means. A ``ValueError``
    names the setting, the rule and the value. Settings made in code, by a preset or read
    from a saved run meet the same rules as flags."""
    for field in dataclasses.fields(settings):
        meta = field_meta(field)
        if not meta:
            continue
        value = getattr(settings, field.name)
        # None is "not set" where the declaration says what that means or defaults to it
        none_allowed = meta["unset"] is not None or field.default is None
        if value is None and none_allowed:
            continue
        # a setting of several values (``nargs``): each of them
        values = tuple(value) if meta["nargs"] is not None else (value,)
        name = field.name if meta["nargs"] is None else f"each of {field.name}"
        or_none = " or None" if none_allowed else ""
        choices, kind = meta["choices"], meta["kind"]
        for v in values:
            if choices is not None and v not in choices:
                raise ValueError(f"{name} must be {' or '.join(map(repr, choices))}, got "
                                 f"{value!r}")
            if kind in _WHOLE and not whole(v, _WHOLE[kind]):
                raise ValueError(f"{name} must be a whole number >= {_WHOLE[kind]}"
                                 f"{or_none}, got {value!r}")
            if kind in _NUMBER:
                test, what = _NUMBER[kind]
                if (isinstance(v, bool) or not isinstance(v, (int, float))
                        or not math.isfinite(v) or not test(v)):
                    raise ValueError(f"{name} must be {what}{or_none}, got {value!r}")
