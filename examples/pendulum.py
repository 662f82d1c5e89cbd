"""Pendulum swing-up written against the API of the paper's code (nrontsis/PILCO).

gymnasium's Pendulum-v1 from hanging down, each action held for SUBS=3 of its steps
(pilco/PendulumSwingUp-v0), observations [cos θ, sin θ, θ̇]: J=4 random rollouts of T=40
steps, 30 basis functions, max action 2 N m, reward around upright [1, 0, 0] with
W = diag(2, 2, 0.3), GP noise fixed at 1e-3, then N=8 iterations each adding a rollout.
Reported per iteration: the rollout's total reward over steps 1..T (as pilco.predict
counts it), the predicted one, and "up": |θ| < 0.3 rad over the last 10 steps.

    python examples/pendulum.py --seed 0
"""
import argparse
import logging
import os

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")  # quiet TensorFlow's C++ start-up lines

import gymnasium as gym
import numpy as np
from gpflow import set_trainable

import pilco.envs  # registers pilco/PendulumSwingUp-v0
from pilco.controllers import RbfController
from pilco.models import PILCO
from pilco.rewards import ExponentialReward


def rollout(env, pilco, timesteps, random=False):
    """``X = [x, u]``, ``Y = x' - x`` and the angle θ after every step."""
    X, Y, theta = [], [], []
    x, _ = env.reset()
    for _ in range(timesteps):
        u = env.action_space.sample() if random else pilco.compute_action(x[None, :])[0, :]
        x_new, _, terminated, truncated, info = env.step(u)
        X.append(np.hstack((x, u)))
        Y.append(x_new - x)
        theta.append(info["theta"])
        x = x_new
        if terminated or truncated:
            break
    return np.stack(X), np.stack(Y), np.array(theta)


parser = argparse.ArgumentParser(description="PILCO pendulum swing-up, paper-code style")
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--iterations", type=int, default=8, help="N: learned rollouts")
parser.add_argument("--rollout-steps", type=int, default=40, help="T: steps and horizon")
parser.add_argument("--basis-functions", type=int, default=30)
parser.add_argument("--maxiter", type=int, default=50, help="optimiser iterations")
parser.add_argument("--output", default="runs/pendulum-seed{seed}/agent.npz")
parser.add_argument("--quiet", action="store_true", help="no library log lines")
args = parser.parse_args()
logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(name)s: %(message)s")
logging.getLogger("pilco").setLevel(logging.WARNING if args.quiet else logging.INFO)
log = logging.getLogger("pendulum")
log.setLevel(logging.INFO)

SUBS, J, N, T = 3, 4, args.iterations, args.rollout_steps  # sub-steps, rollouts, steps
bf, maxiter, max_action = args.basis_functions, args.maxiter, 2.0
target, weights = np.array([1.0, 0.0, 0.0]), np.diag([2.0, 2.0, 0.3])
m_init, S_init = np.reshape([-1.0, 0.0, 0.0], (1, 3)), np.diag([0.01, 0.05, 0.01])
np.random.seed(args.seed)
env = gym.make("pilco/PendulumSwingUp-v0", substeps=SUBS, max_episode_steps=T)
env.reset(seed=args.seed)
env.action_space.seed(args.seed)

X, Y, _ = rollout(env, None, timesteps=T, random=True)
for i in range(1, J):
    X_, Y_, _ = rollout(env, None, timesteps=T, random=True)
    X = np.vstack((X, X_))
    Y = np.vstack((Y, Y_))
state_dim = Y.shape[1]
control_dim = X.shape[1] - state_dim
controller = RbfController(state_dim=state_dim, control_dim=control_dim, num_basis_functions=bf,
                           max_action=max_action)
R = ExponentialReward(state_dim=state_dim, t=target, W=weights)
pilco = PILCO((X, Y), controller=controller, horizon=T, reward=R, m_init=m_init, S_init=S_init)
for model in pilco.mgpr.models:  # for numerical stability, fix the GPs' noise variance
    model.likelihood.variance.assign(0.001)
    set_trainable(model.likelihood.variance, False)

first_up = up = None
for it in range(1, N + 1):
    pilco.optimize_models(maxiter=maxiter, restarts=2)
    pilco.optimize_policy(maxiter=maxiter, restarts=2)
    _, _, predicted = pilco.predict(m_init, S_init, T)
    X_new, Y_new, theta = rollout(env, pilco, timesteps=T)
    states = X_new[:, :state_dim] + Y_new  # x_1 .. x_T
    total = sum(float(R.compute_reward(s[None, :], np.zeros((3, 3)))[0][0, 0]) for s in states)
    up = len(theta) >= 10 and bool(np.all(np.abs(theta[-10:]) < 0.3))
    first_up = first_up or (it if up else None)
    log.info("iteration %d: return %.2f (predicted %.2f), final |θ| %.2f rad, up: %s", it,
             total, float(predicted[0, 0]), abs(theta[-1]), up)
    X = np.vstack((X, X_new))
    Y = np.vstack((Y, Y_new))
    pilco.mgpr.set_data((X, Y))

path = pilco.save(args.output.format(seed=args.seed))
assert len(pilco.data[0]) == len(X), "the agent must hold every transition"
print(f"seed {args.seed}: up first at iteration {first_up}, up in the last: {up}; "
      f"{len(X)} transitions, agent saved to {path}")
