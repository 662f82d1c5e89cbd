"""Argument checks: bad input is reported where it enters, before TensorFlow sees it.

Every check raises :class:`ValueError` (wrong values or shapes) or :class:`TypeError`
(wrong kinds of object) whose message names the argument and the problem, and returns
the value in the form the caller stores (float64 arrays, plain Python numbers). All
argument checks of the package live here.

=================  ==============================================================
module             checks
=================  ==============================================================
``arrays``         arrays of finite numbers, data sets ``(X, Y)``, action bounds,
                   weight matrices, noise factors
``states``         measured states, covariance matrices, Gaussians ``N(m, s)``
``scalars``        counts, positive numbers, seeds, flags, options, indices
``components``     controllers, rewards, squash functions
``files``          file paths, the format version recorded in a pilco file
=================  ==============================================================

The package imports only NumPy and the standard library at import time (the NumPy-only
:mod:`pilco.deploy` uses it); :func:`check_gaussian` imports TensorFlow when called.
"""
from .arrays import (as_2d_float, check_columns, check_data, check_entries, check_matrix,
                     check_max_action, check_noise_scales, check_pair, check_transitions,
                     check_weight_matrix)
from .components import check_controller, check_reward, check_reward_list, check_squash
from .files import check_format_version, check_path
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
    "check_reward",
    "check_controller",
    "check_option",
    "check_entries",
    "check_weight_matrix",
    "check_reward_list",
    "check_pair",
    "check_path",
    "check_format_version",
]
