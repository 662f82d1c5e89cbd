"""Rewards and controllers of your own in agent files: the ``get_config`` protocol.

pilco's own rewards and controllers are stored by :mod:`pilco.models.storage` field by
field. Any other class is stored when it follows this protocol (no base class, no
registration):

- ``get_config(self) -> dict``: the keyword arguments that rebuild it, JSON-ready
  (numbers, strings, booleans, None, lists and dicts of them; NumPy arrays and scalars
  are turned into lists and numbers here);
- optionally a classmethod ``from_config(cls, config)``; without it ``cls(**config)``;
- the class is importable as ``module:QualifiedName`` where the agent is loaded (defined
  at the top level of a module, e.g. the module of a task run with ``pilco run
  mymod:TASK``; a class defined in a script's ``__main__`` loads only in that script).

Its ``gpflow.Parameter`` s (:func:`gpflow.utilities.parameter_dict`, by attribute path)
are stored as :mod:`pilco.models.storage` stores every parameter (values, raw variables,
trainable flags) and assigned after the object is rebuilt, so a trained parameter comes
back as trained, bit for bit.
"""
from __future__ import annotations

import importlib
import json
import logging
from typing import Any, Dict, Tuple

import gpflow
import numpy as np

__all__ = ["CUSTOM", "is_storable", "custom_spec", "build_custom"]

logger = logging.getLogger(__name__)

#: the ``type`` of a stored component that follows the protocol
CUSTOM = "custom"


def is_storable(obj) -> bool:
    """True when ``obj`` follows the ``get_config`` protocol."""
    return callable(getattr(obj, "get_config", None))


def _json_ready(value, where: str):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {str(k): _json_ready(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise TypeError(f"{where} is a {type(value).__name__}: get_config() must return "
                    f"numbers, strings, lists, dicts or NumPy arrays")


def custom_spec(obj, what: str) -> Tuple[dict, Dict[str, gpflow.Parameter]]:
    """The metadata of ``obj`` (a ``what``, e.g. "reward") under the protocol, and its
    parameters by path, which the caller stores (:mod:`pilco.models.storage`, as it
    stores every parameter). TypeError naming the missing piece when ``obj`` does not
    follow the protocol."""
    kind = type(obj)
    name = f"{kind.__module__}:{kind.__qualname__}"
    if not is_storable(obj):
        raise TypeError(f"cannot save a {what} of type {kind.__name__}: define "
                        f"get_config() returning the keyword arguments that rebuild it "
                        f"(pilco.models.custom)")
    if "<locals>" in kind.__qualname__:
        raise TypeError(f"cannot save a {what} of type {kind.__name__}: the class is "
                        f"defined inside a function; define it at a module's top level")
    if kind.__module__ == "__main__":
        logger.warning("the %s %s is defined in __main__: only this script can load the "
                       "saved agent", what, kind.__name__)
    config = _json_ready(obj.get_config(), f"{kind.__name__}.get_config()")
    json.dumps(config)
    params = gpflow.utilities.parameter_dict(obj)
    return dict(type=CUSTOM, cls=name, config=config, params=sorted(params)), params


def build_custom(spec: dict, path, what: str) -> Tuple[Any, Dict[str, gpflow.Parameter]]:
    """The ``what`` stored by :func:`custom_spec`, rebuilt from its config, and its
    parameters by path, to which the caller assigns the stored values. ValueError naming
    the class when it cannot be imported or rebuilt, or lacks a saved parameter."""
    name = spec.get("cls", "")
    module, _, qualname = name.partition(":")
    try:
        found: Any = importlib.import_module(module)
        for part in qualname.split("."):
            found = getattr(found, part)
    except (ImportError, AttributeError, ValueError) as err:
        raise ValueError(f"{path}: the {what} class {name!r} cannot be imported ({err}); "
                         f"is its module on PYTHONPATH?") from err
    config = spec.get("config", {})
    try:
        from_config = getattr(found, "from_config", None)
        obj = from_config(config) if callable(from_config) else found(**config)
    except Exception as err:  # a user's constructor: say which one failed
        raise ValueError(f"{path}: the {what} {name!r} cannot be rebuilt from its saved "
                         f"config ({type(err).__name__}: {err})") from err
    params = gpflow.utilities.parameter_dict(obj)
    missing = sorted(set(spec.get("params", [])) - set(params))
    if missing:
        raise ValueError(f"{path}: the rebuilt {what} {name!r} has no parameter(s) "
                         f"{', '.join(missing)} that were saved")
    return obj, params
