"""The task flags of a sweep's runs: the seed list, ``--set``/``--grid`` assignments and
the settings (one per combination of ``--grid`` values) with their flags, each key
checked against the task's argument parser (the sweep then reads each setting as a run
will, :meth:`pilco.tasks.base.Task.read_settings`, before anything runs: a typo or a
refused value fails in a second, not in every run)."""
from __future__ import annotations

import argparse
import itertools
import re
from typing import Any, List, Optional, Sequence, Tuple

__all__ = ["RESERVED", "parse_seeds", "parse_assignment", "setting_flags", "settings"]

#: flags the sweep passes to every run itself (``--set``/``--grid`` keys may not name them)
RESERVED = ("seed", "output", "resume", "quiet", "no_render", "no_figures", "help")

_KEY = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")
_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


def parse_seeds(text: str) -> List[int]:
    """``"0-19"``, ``"0,3,5"`` or a mixture (``"0-4,10,12-13"``) -> sorted distinct seeds."""
    seeds = set()
    if not isinstance(text, str) or not text.strip():
        raise ValueError("empty seed list")
    for part in text.split(","):
        part = part.strip()
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not m:
            raise ValueError(f"bad seed or range {part!r} (use e.g. 0-19, 0,3,5 or 0-4,10)")
        first = int(m.group(1))
        last = int(m.group(2)) if m.group(2) is not None else first
        if last < first:
            raise ValueError(f"seed range {part!r} runs backwards")
        if last >= 2 ** 31:
            raise ValueError(f"seed {last} too large (at most {2 ** 31 - 1})")
        seeds.update(range(first, last + 1))
    return sorted(seeds)


def parse_assignment(text: str, grid: bool = False) -> Tuple[str, Any]:
    """``"KEY=VALUE"`` -> ``(key, value)``; with ``grid``, ``"KEY=V1,V2"`` -> ``(key,
    [v1, v2])``. Keys use underscores or dashes (``max_data`` is ``--max-data``)."""
    if "=" not in text:
        raise ValueError(f"{text!r} is not KEY=VALUE")
    key, value = text.split("=", 1)
    key = key.strip().lstrip("-").replace("-", "_")
    if not _KEY.match(key):
        raise ValueError(f"bad key {key!r} in {text!r}")
    if key in RESERVED:
        raise ValueError(f"--{key.replace('_', '-')} is set by the sweep itself")
    if not grid:
        if value == "":
            raise ValueError(f"no value in {text!r}")
        return key, value
    values = value.split(",")
    if any(v == "" for v in values):
        raise ValueError(f"empty value in {text!r}")
    if len(set(values)) != len(values):
        raise ValueError(f"repeated value in {text!r}")
    return key, values


def _option(key: str) -> str:
    return "--" + key.replace("_", "-")


def setting_flags(key: str, value: str, parser: Optional[argparse.ArgumentParser]
                  ) -> List[str]:
    """The task flags of ``key=value``: ``["--key", value]``, or for a flag without value
    (``store_true``) ``["--key"]`` when ``value`` is true and ``[]`` when false (for an
    ``--key/--no-key`` flag ``["--no-key"]``).

    With a ``parser`` the flag must be one of its options. Without one, ``true`` and
    ``false`` are taken as such a flag.
    """
    option = _option(key)
    if parser is not None:
        action = next((a for a in parser._actions  # argparse has no API
                       if option in a.option_strings), None)
        if action is None:
            raise ValueError(f"the task has no flag {option} (from {key}={value}); see "
                             f"{parser.prog} --help")
        if action.nargs != 0:
            return [option, value]
        if isinstance(action, argparse.BooleanOptionalAction) and value.lower() in _FALSE:
            return ["--no-" + option[2:]]  # a flag that is on by default
    if value.lower() in _TRUE:
        return [option]
    if value.lower() in _FALSE:
        return []
    if parser is not None:
        raise ValueError(f"{option} takes no value: write {key}=true or {key}=false")
    return [option, value]


def _label(items: Sequence[Tuple[str, str]]) -> str:
    if not items:
        return "default"
    text = ",".join(f"{k}={v}" for k, v in items)
    return re.sub(r"[^A-Za-z0-9._=,+-]", "_", text)


def settings(fixed: Sequence[Tuple[str, str]], grid: Sequence[Tuple[str, List[str]]],
             parser: Optional[argparse.ArgumentParser]) -> List[Tuple[str, List[str]]]:
    """``[(label, flags)]``: one setting per combination of the ``grid`` values, each
    with the ``fixed`` assignments; label ``default`` without any."""
    keys = [k for k, _ in fixed] + [k for k, _ in grid]
    repeated = sorted({k for k in keys if keys.count(k) > 1})
    if repeated:
        raise ValueError(f"key(s) given more than once in --set/--grid: {', '.join(repeated)}")
    out = []
    for combo in itertools.product(*[values for _, values in grid]):
        items = list(fixed) + [(k, v) for (k, _), v in zip(grid, combo)]
        flags = [f for k, v in items for f in setting_flags(k, v, parser)]
        out.append((_label(items), flags))
    labels = [label for label, _ in out]
    if len(set(labels)) != len(labels):
        raise ValueError("two settings get the same directory name; use plainer values")
    return out
