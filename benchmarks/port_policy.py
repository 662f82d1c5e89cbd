"""Time ``optimize_policy(maxiter=10)`` of the reference GPflow port (nrontsis/PILCO).

Run by ``bench_policy.py --port PATH --port-python PYTHON`` in a fresh process of the
port's own environment (TensorFlow 2 and GPflow 2; the port needs ``pandas<2.3`` and
``numpy<2``), on the problem ``bench_policy.py`` writes to an ``.npz`` file: the same
transitions, dynamics-GP hyperparameters (noise fixed), reward, start distribution,
horizon and initial policy as this library's run. Nothing of the port is copied here;
it is imported from the checkout given by ``--port``.

Prints one JSON line: the seconds of the ``optimize_policy`` call (tracing and
compilation included, as for this library, nothing evaluated before it), the expected
return after it (the port's own objective, which sums the rewards of steps 0..H-1) and
the process's peak memory.

Usage (normally through ``bench_policy.py``)::

    /path/to/port-venv/bin/python benchmarks/port_policy.py --port /path/to/PILCO problem.npz
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import resource
import sys
import time


def peak_memory_mb() -> float:
    """Peak resident memory of this process [MB]. Linux's VmHWM belongs to this program
    alone; ``ru_maxrss`` (the fallback) also counts the parent's memory at ``fork``.
    Standard library only: ``bench_policy.py`` uses it too."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("problem", help=".npz written by bench_policy.py")
    parser.add_argument("--port", required=True, help="checkout of nrontsis/PILCO")
    parser.add_argument("--maxiter", type=int, default=10)
    args = parser.parse_args(argv)
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    sys.path.insert(0, os.path.abspath(args.port))

    import numpy as np
    import gpflow
    from gpflow import set_trainable

    from pilco.controllers import RbfController  # the port's package, from --port
    from pilco.models import PILCO
    from pilco.rewards import ExponentialReward

    p = np.load(args.problem)
    X, Y = p["X"], p["Y"]
    D, U = Y.shape[1], X.shape[1] - Y.shape[1]
    nb = p["centers"].shape[0]
    controller = RbfController(state_dim=D, control_dim=U, num_basis_functions=nb,
                               max_action=float(p["max_action"]))
    for i, m in enumerate(controller.models):
        m.X.assign(p["centers"])  # shared by the outputs
        m.Y.assign(p["targets"][:, i:i + 1])
        m.kernel.lengthscales.assign(p["policy_lengthscales"][i])
    reward = ExponentialReward(state_dim=D, W=p["W"], t=p["t"])
    agent = PILCO((X, Y), controller=controller, horizon=int(p["horizon"]), reward=reward,
                  m_init=p["m_init"], S_init=p["S_init"])
    for i, m in enumerate(agent.mgpr.models):
        m.kernel.lengthscales.assign(p["lengthscales"][i])
        m.kernel.variance.assign(float(p["variance"][i]))
        m.likelihood.variance.assign(float(p["noise"][i]))
        set_trainable(m.likelihood.variance, False)

    out = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out):  # the port prints its own timing line
        agent.optimize_policy(maxiter=args.maxiter)
    seconds = time.perf_counter() - t0
    after = float(agent.compute_reward().numpy().ravel()[0])
    print(json.dumps({"port_optimize_policy_seconds": seconds,
                      "port_expected_return_after": after,
                      "port_peak_memory_mb": peak_memory_mb(),
                      "port_gpflow": gpflow.__version__}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
