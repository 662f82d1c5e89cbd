"""pilco/TwoCarsCrossing-v0: the two cars' dynamics, start, reward, the collision flag and
the distance the loop reads."""
from __future__ import annotations

import gymnasium
import numpy as np
import pytest

from pilco.envs import CROSSING_ID, TwoCarsCrossing
from pilco.envs.crossing import CROSSING_START


def drive(action, steps=25, seed=0):
    env = gymnasium.make(CROSSING_ID)
    x, info = env.reset(seed=seed)
    states, infos, rewards = [x], [info], []
    for _ in range(steps):
        x, r, terminated, truncated, info = env.step(np.array([action]))
        states.append(x)
        infos.append(info)
        rewards.append(r)
        assert not terminated
    assert truncated  # 25 steps of the registered id
    return np.array(states), infos, np.array(rewards)


def test_one_step_by_hand_and_the_action_bound():
    env = TwoCarsCrossing(start_std=0.0)
    x, info = env.reset(seed=1)
    np.testing.assert_array_equal(x, CROSSING_START)
    assert info == {"distance": 7.0, "collision": False}
    y, r, *_ = env.step([0.3])
    np.testing.assert_allclose(y, [-6.0 + 0.5, 1.0 + 0.5 * (0.3 - 0.001), -5.0 + 0.5, 1.0])
    assert r == -1.0
    z, *_ = env.step([5.0])  # clipped to 0.4
    assert z[1] == pytest.approx(y[1] + 0.5 * (0.4 - 0.001 * y[1]))
    with pytest.raises(ValueError, match="one finite acceleration"):
        env.step([np.nan])
    with pytest.raises(RuntimeError, match="reset"):
        TwoCarsCrossing().step([0.0])


def test_the_start_is_noisy_and_seeded():
    a, _ = TwoCarsCrossing().reset(seed=3)
    b, _ = TwoCarsCrossing().reset(seed=3)
    c, _ = TwoCarsCrossing().reset(seed=4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c) and np.all(np.abs(a - CROSSING_START) < 0.2)


def test_coasting_collides_and_braking_never_arrives():
    # at constant speed the first car reaches the crossing while the second is in it
    states, infos, rewards = drive(0.0)
    assert any(i["collision"] for i in infos)
    assert infos[-1]["distance"] == 0.0 and rewards[-1] == 1.0
    # braking hard: no collision, but the first car stops short of the crossing
    states, infos, rewards = drive(-0.4)
    assert not any(i["collision"] for i in infos)
    assert np.all(rewards == -1.0) and infos[-1]["distance"] > 4.0
    # accelerating hard is not enough: the first car is still in the crossing when the
    # second enters it (step 8); a safe policy waits for the second car to pass
    states, infos, rewards = drive(0.4)
    assert any(i["collision"] for i in infos) and rewards[-1] == 1.0
    collided = [bool(abs(s[0]) <= 1.0 and abs(s[2]) <= 1.0) for s in states]
    assert collided == [i["collision"] for i in infos]
