"""Start distributions of the policy objective: one per task.

A single-task agent has one start ``N(m_init [1, D], S_init [D, D])``. A multi-task agent
(Deisenroth et al., "Multi-task policy search for robotics", ICRA 2014) has T of them,
``m_init [T, D]`` with its task's context (e.g. the target) in the context dimensions of
each row, and either one covariance ``S_init [D, D]`` shared by all tasks or one per task
``S_init [T, D, D]``; the policy objective sums the expected returns of all T.
"""
from __future__ import annotations

from typing import Tuple

import numpy as np

from ..validation import check_covariance, check_gaussian

__all__ = ["check_starts", "check_task", "start_mixture", "flank_points", "start_samples",
           "check_spread", "check_start_points"]


def _numpy(x):
    """``x`` as an array if it is array-like (tensors included), else ``x`` unchanged (the
    checks below then report its type)."""
    if callable(getattr(x, "numpy", None)):
        return x.numpy()
    if isinstance(x, (str, bytes)) or x is None:
        return x
    try:
        return np.asarray(x)
    except (TypeError, ValueError):  # ragged lists: the checks below say so
        return x


def check_starts(m_init, S_init, state_dim: int,
                 name: str = "initial state") -> Tuple[np.ndarray, np.ndarray, bool]:
    """Check T start distributions; return them as float64 arrays.

    Shapes: ``m_init`` [D], [1, D] (one task) or [T, D] (one start per row);
    ``S_init`` [D, D] (shared by all tasks) or [T, D, D] (one per task) ->
    m [T, D], S [T, D, D], shared (True when one covariance serves every task).

    One task is checked exactly as :func:`pilco.validation.check_gaussian` checks a
    state (the same messages); with several, each message names the task.
    """
    D = state_dim
    m = _numpy(m_init)
    s = _numpy(S_init)
    s_rank = getattr(s, "ndim", None)
    m_rank = getattr(m, "ndim", None)
    if m_rank is not None and m_rank > 2:
        raise ValueError(f"{name} mean must have shape (T, {D}) (one start per task), got "
                         f"{m.shape}")
    rows = m.shape[0] if m_rank == 2 else 1
    if rows <= 1:
        if s_rank == 3 and s.shape[0] == 1:
            s = s[0]
        elif s_rank == 3:
            raise ValueError(f"{name} covariance holds {s.shape[0]} covariances "
                             f"(shape {s.shape}) but the mean has one start")
        m_t, s_t = check_gaussian(m, s, D, name)
        return m_t.numpy().reshape(1, D), s_t.numpy().reshape(1, D, D), True
    if m.shape[1] != D:
        raise ValueError(f"{name} mean must have shape (T, {D}) (one start per task), got "
                         f"{m.shape}")
    T = rows
    shared = s_rank != 3
    if shared:
        s = check_covariance(s, D, f"{name} covariance")
        covariances = [s] * T
    else:
        if s.shape[0] != T:
            raise ValueError(f"{name} covariance must have shape ({D}, {D}) (shared by all "
                             f"tasks) or ({T}, {D}, {D}) (one per task), got {s.shape}")
        covariances = list(s)
    means, covs = [], []
    for i in range(T):
        m_t, s_t = check_gaussian(m[i], covariances[i], D, f"task {i}'s {name}")
        means.append(m_t.numpy().reshape(D))
        covs.append(s_t.numpy())
    return np.stack(means), np.stack(covs), shared


def check_task(task, num_tasks: int) -> int:
    """A task index in ``range(num_tasks)``, or a clear error."""
    if isinstance(task, (bool, np.bool_)) or not isinstance(task, (int, np.integer)):
        raise TypeError(f"task must be an integer index, got {task!r}")
    if not 0 <= task < num_tasks:
        raise ValueError(f"task {int(task)} does not exist: the agent has {num_tasks} "
                         f"start distribution(s), tasks 0 to {num_tasks - 1}")
    return int(task)


def check_spread(spread, state_dim: int, what: str = "start mixture spread",
                 mixture: bool = True):
    """``None`` or 0 (off), else a float ``0 < spread < sqrt(D + 1/2)`` for a start mixture
    (the components' covariance ``(1 - 2 spread² / (2D + 1)) S`` must stay positive), any
    finite number > 0 without ``mixture`` (a start scale); messages name it ``what``."""
    if spread is None:
        return None
    if isinstance(spread, (bool, np.bool_)) or not isinstance(spread, (int, float, np.number)):
        raise TypeError(f"{what} must be a number or None, got {spread!r}")
    spread = float(spread)
    if spread == 0.0:
        return None
    if mixture:
        limit = float(np.sqrt(state_dim + 0.5))
        if not 0.0 < spread < limit:
            raise ValueError(f"{what} must be in (0, {limit:.3f}) for a "
                             f"{state_dim}-dimensional state (0 or None: no mixture), got "
                             f"{spread}")
    elif not (spread > 0.0 and np.isfinite(spread)):
        raise ValueError(f"{what} must be a finite number > 0 (0 or None: none), got "
                         f"{spread}")
    return spread


def start_mixture(m, S, spread: float) -> Tuple[np.ndarray, np.ndarray]:
    """The start distribution ``N(m, S)`` as an equal-weight mixture of 2D + 1 narrower
    Gaussians with the same mean and covariance: one at ``m`` and two at
    ``m ± spread * sqrt(λ_i) v_i`` along each eigenvector ``v_i`` of ``S`` (eigenvalue
    ``λ_i``), each with covariance ``c S``, ``c = 1 - 2 spread² / (2D + 1)``.

    The mixture's mean is ``m`` and its covariance ``c S + (2 spread² / (2D + 1)) S = S``.
    Propagated one by one, the components show the policy objective what happens from
    the start distribution's flanks, which a single moment-matched Gaussian averages
    away (a policy that fails from starts 1.5 standard deviations out can still be
    predicted to succeed from ``N(m, S)`` as a whole).

    Shapes: m [D], S [D, D] -> means [2D + 1, D], covariance [D, D] (shared).
    """
    m = np.asarray(m, dtype=np.float64).reshape(-1)
    S = np.asarray(S, dtype=np.float64)
    D = m.shape[0]
    spread = check_spread(spread, D)
    if spread is None:
        return m[None], S
    c = 1.0 - 2.0 * spread ** 2 / (2 * D + 1)
    return np.concatenate([m[None], flank_points(m, S, spread)]), c * S


def _principal_axes(S) -> Tuple[np.ndarray, np.ndarray]:
    """The standard deviations ``sqrt(λ_i)`` [D] along the eigenvectors ``v_i`` (the
    columns of V [D, D]) of the symmetrised covariance ``S`` (zero eigenvalues allowed)."""
    S = np.asarray(S, dtype=np.float64)
    lam, V = np.linalg.eigh(0.5 * (S + S.T))
    return np.sqrt(np.clip(lam, 0.0, None)), V


def flank_points(m, S, spread: float) -> np.ndarray:
    """The 2D states ``m ± spread * sqrt(λ_i) v_i`` along the eigenvectors ``v_i`` of
    ``S`` (eigenvalues ``λ_i``): ``spread`` standard deviations out along each principal
    axis of ``N(m, S)``, in the order ``+v_1, -v_1, +v_2, ...``.

    Shapes: m [D], S [D, D], spread > 0 -> [2D, D].
    """
    m = np.asarray(m, dtype=np.float64).reshape(-1)
    std, V = _principal_axes(S)
    steps = spread * std[None, :] * V  # column i: step along v_i
    return np.stack([m + sign * steps[:, i] for i in range(m.shape[0]) for sign in (1.0, -1.0)])


def start_samples(m, S, count: int, seed: int) -> np.ndarray:
    """``count`` draws from ``N(m, S)`` (a covariance with zero eigenvalues allowed), from
    the generator of ``seed``. Shapes: m [D], S [D, D] -> [count, D]."""
    m = np.asarray(m, dtype=np.float64).reshape(-1)
    z = np.random.default_rng(seed).standard_normal((int(count), m.shape[0]))
    std, V = _principal_axes(S)
    root = V * std[None, :]  # root @ root.T == S
    return m[None, :] + z @ root.T


def check_start_points(points, num_tasks: int, state_dim: int):
    """Known start states of the policy objective: None (or an empty array) for none,
    else finite numbers of shape [P, D] (one task) or [T, P, D] (one set per task).
    Returns None or a float64 array [T, P, D]."""
    if points is None:
        return None
    arr = _numpy(points)
    if not isinstance(arr, np.ndarray) or arr.dtype == object or arr.dtype.kind not in "biuf":
        raise TypeError(f"start points must be an array of numbers, got {type(points).__name__}")
    if arr.size == 0:
        return None
    if arr.ndim == 2 and num_tasks == 1:
        arr = arr[None]
    T, D = num_tasks, state_dim
    if arr.ndim != 3 or arr.shape[0] != T or arr.shape[2] != D:
        want = f"(P, {D}) or (1, P, {D})" if T == 1 else f"({T}, P, {D}) (one set per task)"
        raise ValueError(f"start points must have shape {want}, got {arr.shape}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError("start points must be finite")
    return arr
