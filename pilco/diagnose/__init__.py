"""Why did a learned episode of a run fail: the model, the optimiser or the objective?

``python -m pilco.diagnose RUN_DIR [--episode K]`` reopens a run directory written by a
task (``python -m pilco.tasks``, the examples, a seed sweep's ``DIR/SETTING/seed-S``),
rebuilds the agent as it was when learned episode K (default the last) ran, measures the
model, the optimiser and the objective on that episode, gives a verdict by explicit rules,
prints the report and writes it to ``RUN_DIR/diagnosis.json``.

The same from Python::

    from pilco.diagnose import diagnose, format_report, open_run, write_diagnosis

    exp = open_run("runs/reacher-seed5")
    try:
        result = diagnose(exp, episode=3, restarts=3)
    finally:
        exp.close()
    write_diagnosis(result, "runs/reacher-seed5/diagnosis.json")
    print(format_report(result))

Public API
    :func:`open_run` (a run directory as a resumed :class:`~pilco.experiment.Experiment`,
    :func:`pilco.tasks.open_run`),
    :func:`diagnose` (the checks and the verdict of one learned episode, as a JSON-ready
    dict), :func:`write_diagnosis`, :func:`format_report` (the printed report),
    :func:`verdict` and :data:`VERDICTS` (the rules on their own), :class:`Thresholds`
    (their numbers), :func:`agent_of_episode`, :func:`replay_learning` and
    :func:`action_error` (the agent of an earlier episode), :func:`main` and
    :func:`build_parser` (the command line).

=================  ==============================================================
module             job
=================  ==============================================================
``replay``         the agent as it was when an episode ran (saved or replayed)
``geometry``       the distance a saturating cost measures, the cost's slope
``checks``         the measurements: model (one step, open loop, multi-step),
                   optimiser (re-optimised policies), objective (the cost's slope)
``thresholds``     :class:`Thresholds`, the numbers the checks and rules judge by
``rules``          :func:`verdict`: the verdict rules, and the notes
``diagnosis``      :func:`diagnose`: all of the above for one episode; the JSON
``report``         :func:`format_report`: the result as text
``cli``            the command line (``__main__`` runs it)
=================  ==============================================================

The names above are loaded on first use, so that importing this package (as
``python -m pilco.diagnose`` does before parsing its flags) does not import TensorFlow.
"""
from __future__ import annotations

import importlib

#: public name -> the module that defines it, relative to this package (``open_run`` is
#: the tasks' own, :func:`pilco.tasks.open_run`)
_EXPORTS = {
    "open_run": "..tasks",
    "diagnose": ".diagnosis", "write_diagnosis": ".diagnosis",
    "format_report": ".report",
    "verdict": ".rules", "VERDICTS": ".rules",
    "Thresholds": ".thresholds",
    "agent_of_episode": ".replay", "replay_learning": ".replay", "action_error": ".replay",
    "build_parser": ".cli", "main": ".cli",
}

__all__ = list(_EXPORTS)


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(_EXPORTS))
