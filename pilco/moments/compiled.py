"""What the moment-matching graph needs to be compiled by XLA once per run.

Two separate concerns, both used by :class:`pilco.models.rollout.Rollout` when its policy
objective is compiled with XLA (``jit_compile``):

* **XLA-compatible linear algebra.** XLA on CPU has no ``LogMatrixDeterminant`` kernel, so
  a graph traced inside :func:`xla_compatible` computes log-determinants without it: of a
  symmetric positive definite matrix through its Cholesky factor (:func:`logdet_spd`), of
  a general one through a QR factorisation (:func:`logdet`). Outside that context the
  graph keeps TensorFlow's ``slogdet``, so the default (TensorFlow graph) path is the
  same operation for operation, and its rounding is unchanged.
* **Fixed data sizes.** XLA compiles one program per input shape, and a PILCO run adds
  transitions every episode. :func:`pad_factorization` pads a GP's factorisation to a
  few fixed sizes (:func:`bucket_size`) with centres whose weights are exactly zero:
  ``beta`` and ``K^-1`` are zero in the padded rows and columns, so every padded
  centre's contribution to the predicted mean, covariance and input-output covariance
  is a product with an exact zero. Predictions are unchanged up to the order of
  floating-point summation.
* **The same program in every process.** TensorFlow names the functions a trace creates
  with a process-wide counter (``__inference__tf_eval_23771``, ``while_body_18504``), and
  those names are part of the program that XLA's persistent compilation cache is keyed
  on: the same objective traced by another run, whose GP training had created other
  graphs before, gets other names and misses the cache. :func:`align_graph_names` moves
  the counter to a round value just before a trace, so that the trace's names repeat.
"""
from __future__ import annotations

import contextlib
import math
import threading
from typing import Iterator

import tensorflow as tf

from .factorization import Factorization

__all__ = ["xla_compatible", "in_xla_compatible", "log_determinant", "logdet_spd", "logdet",
           "bucket_size", "pad_factorization", "align_graph_names", "NAME_ALIGNMENT"]

_mode = threading.local()

#: :func:`align_graph_names` moves TensorFlow's name counter to a multiple of this
NAME_ALIGNMENT = 1 << 20


@contextlib.contextmanager
def xla_compatible(on: bool = True) -> Iterator[None]:
    """Graphs traced inside this context (with ``on``) use only operations XLA compiles
    on CPU (see the module docstring). Nesting restores the outer setting on exit."""
    before = getattr(_mode, "on", False)
    _mode.on = bool(on)
    try:
        yield
    finally:
        _mode.on = before


def in_xla_compatible() -> bool:
    """True while tracing inside :func:`xla_compatible`."""
    return getattr(_mode, "on", False)


def logdet_spd(A: tf.Tensor) -> tf.Tensor:
    """log det of symmetric positive definite matrices through their Cholesky factors.

    Shapes: A [..., D, D] -> [...]. Differentiable through TensorFlow's Cholesky gradient
    (callers with their own gradient, such as the moment matching's inverse and
    log-determinant, use only the value)."""
    L = tf.linalg.cholesky(A)
    return 2.0 * tf.reduce_sum(tf.math.log(tf.linalg.diag_part(L)), axis=-1)


@tf.custom_gradient
def logdet(A: tf.Tensor):
    """log |det A| of square matrices through a QR factorisation (XLA has no
    ``LogMatrixDeterminant`` on CPU). Shapes: A [..., D, D] -> [...].

    The gradient is ``A^-T`` (as ``slogdet``'s), computed in the backward pass."""
    R = tf.linalg.qr(A, full_matrices=False)[1]
    value = tf.reduce_sum(tf.math.log(tf.abs(tf.linalg.diag_part(R))), axis=-1)

    def grad(g):
        return g[..., None, None] * tf.linalg.adjoint(tf.linalg.inv(A))

    return value, grad


def log_determinant(A: tf.Tensor, spd: bool = False) -> tf.Tensor:
    """log det of square matrices with a positive determinant, as the graph being traced
    needs it: TensorFlow's ``slogdet`` (the default path, unchanged), or inside
    :func:`xla_compatible` :func:`logdet_spd` (``spd``: symmetric positive definite) or
    :func:`logdet`. Shapes: A [..., D, D] -> [...]."""
    if not in_xla_compatible():
        return tf.linalg.slogdet(A)[1]
    return logdet_spd(A) if spd else logdet(A)


def bucket_size(n: int) -> int:
    """The padded size of ``n`` training points: ``n`` rounded up to a multiple of a
    quarter of the largest power of two not above it (at least 8), so that a run whose
    data grow over a factor 2 meets about four sizes, and padding adds at most a quarter.

    >>> [bucket_size(n) for n in (5, 40, 50, 100, 120, 150, 280)]
    [8, 40, 56, 112, 128, 160, 320]
    """
    n = int(n)
    if n < 1:
        raise ValueError(f"bucket_size needs at least one point, got {n}")
    step = max(8, 2 ** max(0, int(math.floor(math.log2(n))) - 2))
    return -(-n // step) * step


def pad_factorization(fact: Factorization, size: int) -> Factorization:
    """``fact`` with its n centres padded to ``size`` by points of zero weight.

    Shapes: centers [n, D] -> [size, D] (the last centre repeated, so no padded centre is
    far from the data and no exponential underflows differently), beta [E, n] ->
    [E, size] (zeros), iK [E, n, n] -> [E, size, size] (zeros outside the top-left block;
    ``None`` stays ``None``). Lengthscales and variances are unchanged. ``size < n`` is a
    ValueError."""
    n = int(fact.centers.shape[0])
    size = int(size)
    if size < n:
        raise ValueError(f"cannot pad {n} centres to {size}")
    if size == n:
        return fact
    extra = size - n
    centers = tf.concat([fact.centers, tf.repeat(fact.centers[-1:], extra, axis=0)], axis=0)
    beta = tf.pad(fact.beta, [[0, 0], [0, extra]])
    iK = None if fact.iK is None else tf.pad(fact.iK, [[0, 0], [0, extra], [0, extra]])
    return Factorization(centers, beta, iK, fact.lengthscales, fact.variance)


def align_graph_names(alignment: int = NAME_ALIGNMENT) -> int:
    """Advance TensorFlow's graph-name counter so that the next name it hands out is a
    multiple of ``alignment``; returns that number.

    Call it just before a trace whose compiled program should be found in XLA's
    persistent cache by other processes (see the module docstring): two processes that
    call it with their counters in the same window of ``alignment`` names trace with the
    same names. The runs of a task differ by a few thousand names before their first
    trace, so with the default (2^20) a run misses the cache only when a window boundary
    falls between two runs' counters (well under 1 % of runs; the run then compiles,
    with the same result). Costs one counter call per skipped name (~0.3 s for 2^20).
    """
    if isinstance(alignment, bool) or not isinstance(alignment, int) or alignment < 1:
        raise ValueError(f"alignment must be a positive int, got {alignment!r}")
    from tensorflow.python.framework import ops  # the counter itself has no public API

    uid = ops.uid()
    skip = (-uid - 1) % alignment  # names to hand out so that the next is aligned
    for _ in range(skip):
        ops.uid()
    return uid + 1 + skip
