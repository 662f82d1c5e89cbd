"""Why did a learned episode of a run fail: the model, the optimiser or the objective?

``python -m pilco.diagnose RUN_DIR [--episode K]`` reopens a run directory written by a
task (``python -m pilco.tasks``, the examples, a seed sweep's ``DIR/SETTING/seed-S``),
diagnoses learned episode K (default the last) with
:func:`pilco.experiment.diagnose.diagnose`, prints the report and writes it to
``RUN_DIR/diagnosis.json``.

=================  ==============================================================
module             job
=================  ==============================================================
``reopen``         :func:`open_run`: a run directory as a resumed experiment
``cli``            the command line (``__main__`` runs it)
=================  ==============================================================

The names above are loaded on first use, so that importing this package (as
``python -m pilco.diagnose`` does before parsing its flags) does not import TensorFlow.
"""
from __future__ import annotations

import importlib

#: public name -> the module of this package that defines it
_EXPORTS = {
    "open_run": "reopen",
    "build_parser": "cli", "main": "cli",
}

__all__ = list(_EXPORTS)


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(_EXPORTS))
