"""The reference port's pendulum swing-up workload, timed phase by phase, for either library.

One script in the API of the paper's code (nrontsis/PILCO), run unchanged against this
library or, with ``--port PATH``, against a checkout of that port (imported from there;
nothing of it is copied here): gymnasium's Pendulum-v1 from hanging down, each action held
for 3 of its steps, observations [cos θ, sin θ, θ̇]; 4 random rollouts of 40 steps, 30
basis functions, max action 2, reward around [1, 0, 0] with W = diag(2, 2, 0.3), GP noise
fixed at 1e-3, then 8 iterations of ``optimize_models(maxiter=50, restarts=2)``,
``optimize_policy(maxiter=50, restarts=2)``, a rollout and ``mgpr.set_data``: the port's
``examples/pendulum_swing_up.py`` with gymnasium instead of gym. The environment is
written here (not ``pilco.envs``) so that the port's package can take the name ``pilco``.

The port's optimisers are GPflow ``Scipy`` instances, which since GPflow 2.9 keep the
compiled objective of one loss across ``minimize`` calls; the port hands its models new
data as arrays, which a compiled objective holds as constants, so with that cache every
GP training and policy search after the first one computes on the first 160 transitions
(whatever ``set_data`` gave it). The port was written for a GPflow without the cache, so
``--port`` turns it off (``compile_cache_size=0``: each call compiles its objective
anew, on the data it has); ``--port-compile-cache`` times the port as it runs with the
cache.

Prints one JSON line: seconds of the whole workload and of each phase (GP training,
policy search, rollouts, per iteration), the number of transitions, whether the pendulum
was up (|θ| < 0.3 rad over the last 10 steps of a rollout) and the peak memory.
``bench_pendulum.py`` runs it for both libraries side by side.

    python benchmarks/pendulum_workload.py [--port /path/to/PILCO] [--iterations 8]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import time

from port_policy import peak_memory_mb

SUBS, J, T = 3, 4, 40  # sub-steps per action, random rollouts, steps per rollout


class HangingPendulum:
    """Pendulum-v1 without time limit, started hanging (θ = π + U(0, 0.01 π), θ̇ = U(0,
    0.01)), each action held for ``SUBS`` steps; ``step`` returns (obs, θ)."""

    def __init__(self, seed: int):
        import gymnasium as gym
        import numpy as np
        self.np = np
        self.env = gym.make("Pendulum-v1").unwrapped
        self.env.reset(seed=seed)
        self.action_space = self.env.action_space
        self.action_space.seed(seed)
        self.rng = np.random.default_rng(seed)

    def _obs(self):
        th, thdot = self.env.state
        return self.np.array([self.np.cos(th), self.np.sin(th), thdot])

    def reset(self):
        high = self.np.array([self.np.pi, 1.0])
        self.env.state = self.rng.uniform(low=0.0, high=0.01 * high)
        self.env.state[0] += self.np.pi
        self.env.last_u = None
        return self._obs()

    def step(self, u):
        for _ in range(SUBS):
            self.env.step(u)
        th = (self.env.state[0] + self.np.pi) % (2 * self.np.pi) - self.np.pi
        return self._obs(), th


def rollout(env, agent, random: bool):
    import numpy as np
    X, Y, theta = [], [], []
    x = env.reset()
    for _ in range(T):
        u = env.action_space.sample() if random else agent.compute_action(x[None, :])[0, :]
        x_new, th = env.step(u)
        X.append(np.hstack((x, u)))
        Y.append(x_new - x)
        theta.append(th)
        x = x_new
    return np.stack(X), np.stack(Y), np.array(theta)


def tolerate_port_printing() -> None:
    """The port's ``optimize_models`` prints its hyperparameters after
    ``pandas.set_option('precision', 3)``, a key that pandas >= 1.4 finds ambiguous
    (``display.precision`` or ``styler.format.precision``) and refuses; the port's
    environment needs pandas < 2.3 for other reasons, and no pandas with wheels for Python
    3.11 accepts that key. Map it to the printing option it meant (output only)."""
    import pandas
    set_option = pandas.set_option

    def set_display_option(key, *rest, **kwargs):
        return set_option("display.precision" if key == "precision" else key, *rest,
                          **kwargs)

    pandas.set_option = set_display_option


def compile_each_call() -> None:
    """Make every ``gpflow.optimizers.Scipy()`` the port creates compile its objective at
    each ``minimize`` call (no cache), as GPflow did before 2.9, so that it optimises on
    the data its models hold at that call."""
    import gpflow
    cached = gpflow.optimizers.Scipy

    class CompileEachCall(cached):
        def __init__(self, compile_cache_size: int = 0) -> None:
            super().__init__(compile_cache_size=compile_cache_size)

    gpflow.optimizers.Scipy = CompileEachCall


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--port", default=None, help="checkout of nrontsis/PILCO to time")
    parser.add_argument("--port-compile-cache", action="store_true",
                        help="keep GPflow's compile cache in the port (its optimisations "
                             "after the first then use the first data; see above)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--iterations", type=int, default=8)
    parser.add_argument("--maxiter", type=int, default=50)
    parser.add_argument("--restarts", type=int, default=2)
    args = parser.parse_args(argv)
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    if args.port:
        sys.path.insert(0, os.path.abspath(args.port))
        tolerate_port_printing()
    start = time.perf_counter()

    import numpy as np
    from gpflow import set_trainable

    from pilco.controllers import RbfController
    from pilco.models import PILCO
    from pilco.rewards import ExponentialReward
    if args.port and not args.port_compile_cache:
        compile_each_call()  # after the imports, whose time counts as set-up

    np.random.seed(args.seed)
    env = HangingPendulum(args.seed)
    X, Y, _ = rollout(env, None, random=True)
    for _ in range(1, J):
        X_, Y_, _ = rollout(env, None, random=True)
        X = np.vstack((X, X_))
        Y = np.vstack((Y, Y_))
    D, U = Y.shape[1], X.shape[1] - Y.shape[1]
    controller = RbfController(state_dim=D, control_dim=U, num_basis_functions=30,
                               max_action=2.0)
    reward = ExponentialReward(state_dim=D, t=np.array([1.0, 0.0, 0.0]),
                               W=np.diag([2.0, 2.0, 0.3]))
    agent = PILCO((X, Y), controller=controller, horizon=T, reward=reward,
                  m_init=np.reshape([-1.0, 0.0, 0.0], (1, 3)),
                  S_init=np.diag([0.01, 0.05, 0.01]))
    for model in agent.mgpr.models:
        model.likelihood.variance.assign(0.001)
        set_trainable(model.likelihood.variance, False)
    setup = time.perf_counter() - start

    iterations = []
    for it in range(1, args.iterations + 1):
        record = {"iteration": it, "transitions": int(len(X))}
        # the port prints as it optimises; its lines are not part of the timing's output
        with contextlib.redirect_stdout(io.StringIO()):
            t0 = time.perf_counter()
            agent.optimize_models(maxiter=args.maxiter, restarts=args.restarts)
            t1 = time.perf_counter()
            agent.optimize_policy(maxiter=args.maxiter, restarts=args.restarts)
            t2 = time.perf_counter()
            X_new, Y_new, theta = rollout(env, agent, random=False)
            t3 = time.perf_counter()
        record.update(model=t1 - t0, policy=t2 - t1, rollout=t3 - t2,
                      up=bool(np.all(np.abs(theta[-10:]) < 0.3)),
                      final_abs_theta=float(abs(theta[-1])))
        iterations.append(record)
        X = np.vstack((X, X_new))
        Y = np.vstack((Y, Y_new))
        agent.mgpr.set_data((X, Y))

    total = time.perf_counter() - start
    print(json.dumps({
        "library": "port" if args.port else "pilco", "seed": args.seed,
        "port_compile_cache": bool(args.port and args.port_compile_cache),
        "seconds": round(total, 2), "setup": round(setup, 2),
        "model": round(sum(r["model"] for r in iterations), 2),
        "policy": round(sum(r["policy"] for r in iterations), 2),
        "rollout": round(sum(r["rollout"] for r in iterations), 2),
        "transitions": int(len(X)), "up_last": iterations[-1]["up"],
        "first_up": next((r["iteration"] for r in iterations if r["up"]), None),
        "iterations": [{k: (round(v, 3) if isinstance(v, float) else v)
                        for k, v in r.items()} for r in iterations],
        "peak_mb": round(peak_memory_mb()),
    }))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
