"""Benchmark of the dynamics model's training: ``MGPR.optimize`` on the paper's reacher
size (10 outputs, 17 inputs) and the cart-pole's (4 outputs, 6 inputs).

Each measurement runs in a fresh process, so that the first call pays tracing and graph
compilation as a new run does: the seconds of the first ``optimize(maxiter=100)`` (tracing
included), of a second one after adding data (the compiled loss is reused), the trace
time and operation count of the loss and its gradient, and the median seconds per loss
+ gradient evaluation. ``batched`` is the library's training loss (all outputs in one
batched computation); ``per-output`` the sum of each output's own GPflow loss, the way
it was computed before, timed in the same run for a side-by-side ratio.

Usage::

    python benchmarks/bench_models.py                     # both problems, 3 rounds
    python benchmarks/bench_models.py --problem reacher --rounds 5 --json out.json
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

SIZES = {"reacher": dict(D=10, U=7, N=100), "cartpole": dict(D=4, U=2, N=120)}


def data(problem: str, extra: int = 0, seed: int = 0):
    """Smooth synthetic transitions of the problem's size (``extra`` more rows)."""
    size = SIZES[problem]
    D, U, N = size["D"], size["U"], size["N"] + extra
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((D + U, D)) / np.sqrt(D + U)
    X = np.concatenate([rng.uniform(-1, 1, (N, D)), rng.uniform(-0.1, 0.1, (N, U))], 1)
    return X, 0.1 * np.tanh(X @ A) + 1e-3 * rng.standard_normal((N, D))


def measure(problem: str, mode: str, repeats: int = 20) -> dict:
    """The figures of one mode in this (fresh) process."""
    import tensorflow as tf

    from pilco.models import MGPR

    threads = int(os.environ.get("BENCH_THREADS", "1"))
    tf.config.threading.set_intra_op_parallelism_threads(threads)
    tf.config.threading.set_inter_op_parallelism_threads(threads)
    def new_model():
        gp = MGPR(data(problem))
        if mode == "per-output":
            gp._batchable = lambda: False  # the per-output path, compared
        return gp

    gp = new_model()
    variables = gp.trainable_variables

    @tf.function(autograph=False)
    def loss_and_gradient():
        with tf.GradientTape() as tape:
            loss = gp.training_loss()  # what optimize minimises
        return loss, tape.gradient(loss, variables)

    t0 = time.perf_counter()
    graph = loss_and_gradient.get_concrete_function().graph
    trace = time.perf_counter() - t0
    loss_and_gradient()
    seconds = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        loss_and_gradient()[0].numpy()
        seconds.append(time.perf_counter() - t0)
    # a new model, so that optimize pays its own tracing as a run's first fit does
    gp = new_model()
    t0 = time.perf_counter()
    gp.optimize(maxiter=100)
    first = time.perf_counter() - t0
    gp.set_data(data(problem, extra=50, seed=1))
    t0 = time.perf_counter()
    gp.optimize(maxiter=100)
    second = time.perf_counter() - t0
    return {"trace_seconds": trace, "operations": len(graph.get_operations()),
            "loss_gradient_seconds": float(np.median(seconds)),
            "first_optimize_seconds": first, "second_optimize_seconds": second,
            "final_loss": float(np.sum(gp._model_losses()))}


def fresh(problem: str, mode: str) -> dict:
    out = subprocess.run([sys.executable, __file__, "--_fresh", problem, mode],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--problem", choices=["reacher", "cartpole", "all"], default="all")
    parser.add_argument("--rounds", type=int, default=3,
                        help="fresh processes per mode, interleaved (medians reported)")
    parser.add_argument("--json", default=None, help="write the results to this file")
    parser.add_argument("--_fresh", nargs=2, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    if args._fresh:
        print(json.dumps(measure(*args._fresh)))
        return 0
    problems = list(SIZES) if args.problem == "all" else [args.problem]
    modes = ("batched", "per-output")
    results = {}
    keys = ("trace_seconds", "operations", "loss_gradient_seconds", "first_optimize_seconds",
            "second_optimize_seconds", "final_loss")
    print(f"{'problem':<9} {'mode':<11} {'trace s':>8} {'ops':>6} {'loss+grad s':>12} "
          f"{'1st optimize s':>15} {'2nd optimize s':>15}")
    for problem in problems:
        runs = {mode: [] for mode in modes}
        for _ in range(args.rounds):
            for mode in modes:
                runs[mode].append(fresh(problem, mode))
        results[problem] = {}
        for mode in modes:
            med = {k: float(np.median([r[k] for r in runs[mode]])) for k in keys}
            med["rounds"] = runs[mode]
            results[problem][mode] = med
            print(f"{problem:<9} {mode:<11} {med['trace_seconds']:8.2f} "
                  f"{med['operations']:6.0f} {med['loss_gradient_seconds']:12.4f} "
                  f"{med['first_optimize_seconds']:15.2f} {med['second_optimize_seconds']:15.2f}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
