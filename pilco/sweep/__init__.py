"""Success rates over many seeds: ``python -m pilco.sweep TASK --seeds 0-19``.

Each run of a sweep is one process ``python -m pilco.tasks TASK --seed S ...`` inside a
Ray task (Ray core: a local Ray by default, an existing cluster with ``--address``); the
results are aggregated per setting into ``sweep.json``, a table and figures.

==============  =================================================================
module          job
==============  =================================================================
``cli``         the command line: its flags, the plan of runs, Ray's start, the end
``flags``       seeds, ``--set``/``--grid``, the settings, their task flags checked
``preflight``   the directory lock, the check of a ``--address`` cluster
``runs``        one Ray task per run, retries, resume, Ctrl-C
``report``      ``sweep.json``: every finished run aggregated per setting
``aggregate``   Wilson intervals, quartiles, per-setting aggregates, the table
``figures``     ``success_rate.png`` and ``distance_bands.png``
==============  =================================================================

Only :mod:`pilco.sweep.runs` needs Ray (imported when a sweep starts); the statistics
need the standard library only.
"""
from .aggregate import aggregate_setting, quartiles, run_success, wilson_interval

__all__ = ["aggregate_setting", "quartiles", "run_success", "wilson_interval"]
