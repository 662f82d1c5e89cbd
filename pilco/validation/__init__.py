"""Argument checks: bad input is reported where it enters, before TensorFlow sees it.

Every check raises :class:`ValueError` (wrong values or shapes) or :class:`TypeError`
(wrong kinds of object) whose message names the argument and the problem, and returns
the value in the form the caller stores (float64 arrays, plain Python numbers).

=================  ==============================================================
module             checks
=================  ==============================================================
``arrays``         arrays of finite numbers, data sets ``(X, Y)``, action bounds,
                   weight matrices, noise factors
``states``         measured states, covariance matrices, Gaussians ``N(m, s)``
``scalars``        counts, positive numbers, seeds, flags, options, indices
``components``     controllers, rewards, squash and other functions
``files``          file paths, the format version recorded in a pilco file
``inputs``         the inputs of prediction methods, eager or traced (the rule of
                   conversion to float64 and what is checked when)
=================  ==============================================================

The package imports only NumPy and the standard library at import time (the NumPy-only
:mod:`pilco.deploy` uses it); :func:`check_gaussian` imports TensorFlow when called.

Who checks what
---------------
Each layer checks the input that enters it:

- **The library** (:mod:`pilco.models`, :mod:`pilco.controllers`, :mod:`pilco.rewards`,
  :mod:`pilco.deploy`, :mod:`pilco.models.storage`) checks the arguments of its public
  functions and constructors with this package. Two kinds of error stay where they
  arise: a file's contents (truncated, an entry missing, an unknown type) are checked
  by its reader, :func:`pilco.deploy.read_npz` and :mod:`pilco.models.storage`; and a
  request the object's current state cannot serve (``restarts > 1`` for a controller
  without ``randomize``, noise factors other than 1 for a sparse model) is refused by the
  method that holds that state. :class:`pilco.rewards.AxisBumpsReward` refuses empty
  ``dims`` and widths <= 0 in its constructor.
- **The environments** (:mod:`pilco.envs`) check their constructor, ``reset`` and
  ``step`` arguments with :mod:`pilco.envs._checks`: :mod:`pilco.envs` imports nothing
  from the rest of pilco (the bottom layer: the environments work without the learning
  library), so it cannot use these checks.
- **The settings of a run** are checked by
  :meth:`pilco.experiment.config.ExperimentConfig.__post_init__`: every way a run is
  configured builds that dataclass (command-line flags; the settings a resumed run reads
  back from ``progress.json``, which are not text and so never pass argparse's ``type=``
  functions; a task's code; the saved config :mod:`pilco.diagnose` replays), so each
  field (whole numbers >= 1, the two-valued options) and the relations between fields
  (``episodes >= random_episodes``, ``max_data`` at least 2 or none) are checked once
  for all of them. The other functions of :mod:`pilco.experiment` refuse what they
  cannot run where they take it (:func:`~pilco.experiment.rollout` without a policy,
  the reconstruction of an episode that was not learned).
- **The command lines**: :mod:`pilco.tasks.settings` turns the text of every task's
  flags into values with the readers ``positive_float``, ``non_negative_float``,
  ``positive_int`` and ``non_negative_int`` (and ``choices=``) that each settings field
  names, so a bad flag is a usage error before anything runs; a task's ``check`` refuses
  settings that conflict with each other (the adaptation's), and :mod:`pilco.tasks`
  checks the name of a task. :mod:`pilco.sweep.cli` checks the sweep's own flags when it plans the
  runs (seed lists, ``--set``/``--grid`` settings, each also parsed by the task's
  parser, ``--address``, CPU counts); :mod:`pilco.sweep` also checks its run
  directories and the counts given to its statistics (:mod:`pilco.sweep.aggregate`).
"""
from .arrays import (as_2d_float, check_columns, check_data, check_entries, check_matrix,
                     check_max_action, check_noise_scales, check_pair, check_transitions,
                     check_weight_matrix)
from .components import (check_callable, check_controller, check_reward, check_reward_list,
                         check_squash)
from .files import check_format_version, check_path
from .inputs import check_points, checked_arguments
from .scalars import (check_bool, check_indices, check_min_rel_improvement,
                      check_non_negative_float, check_option, check_positive_float,
                      check_positive_int, check_ratio_bound, check_seed)
from .states import check_covariance, check_gaussian, check_state_row, check_states

__all__ = [
    "as_2d_float",
    "check_data",
    "check_noise_scales",
    "check_transitions",
    "check_columns",
    "check_state_row",
    "check_gaussian",
    "check_covariance",
    "check_positive_int",
    "check_max_action",
    "check_positive_float",
    "check_non_negative_float",
    "check_min_rel_improvement",
    "check_seed",
    "check_bool",
    "check_indices",
    "check_matrix",
    "check_states",
    "check_ratio_bound",
    "check_squash",
    "check_callable",
    "check_reward",
    "check_controller",
    "check_option",
    "check_entries",
    "check_weight_matrix",
    "check_reward_list",
    "check_pair",
    "check_path",
    "check_format_version",
    "check_points",
    "checked_arguments",
]
