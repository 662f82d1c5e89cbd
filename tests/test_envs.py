"""Behavioural tests of the PILCO environments (cart-pole swing-up, Fetch joint reacher,
pendulum swing-up)."""
from __future__ import annotations

import importlib
import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from scipy.integrate import solve_ivp

import pilco.envs as penvs
from pilco.envs import CARTPOLE_ID, FETCH_DAMAGED_ID, FETCH_ID, CartPoleSwingUp

# ---------------------------------------------------------------------------
# Package / registration
# ---------------------------------------------------------------------------


def test_import_does_not_load_mujoco_and_registers_ids():
    code = (
        "import sys, gymnasium, pilco.envs\n"
        "assert 'mujoco' not in sys.modules, 'mujoco imported'\n"
        "assert 'gymnasium_robotics' not in sys.modules, 'gymnasium_robotics imported'\n"
        "for i in ('pilco/CartPoleSwingUp-v0', 'pilco/FetchJointReacher-v0',"
        " 'pilco/FetchJointReacherDamaged-v0', 'pilco/PendulumSwingUp-v0'):\n"
        "    assert i in gymnasium.registry, i\n"
        "env = gymnasium.make('pilco/CartPoleSwingUp-v0')\n"
        "env.reset(seed=0); env.step([0.0])\n"
        "assert 'mujoco' not in sys.modules\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr


def test_registration_is_idempotent():
    importlib.reload(penvs)  # registers again: must neither fail nor duplicate
    penvs.register_envs()
    assert CARTPOLE_ID in gymnasium.registry


# ---------------------------------------------------------------------------
# Cart-pole
# ---------------------------------------------------------------------------

M, MP, L, B, G = 0.5, 0.5, 0.5, 0.1, 9.82


def reference_ode(state, f, b=B):
    """dynamics_cp.m of the MATLAB PILCO release, written out independently."""
    x, dx, dth, th = state
    s, c = np.sin(th), np.cos(th)
    ddx = (2 * MP * L * dth**2 * s + 3 * MP * G * s * c + 4 * f - 4 * b * dx) / (
        4 * (M + MP) - 3 * MP * c**2
    )
    ddth = (-3 * MP * L * dth**2 * s * c - 6 * (M + MP) * G * s - 6 * (f - b * dx) * c) / (
        4 * L * (MP + M) - 3 * MP * L * c**2
    )
    return np.array([dx, ddx, ddth, dth])


def energy(state, b_unused=None):
    """Energy of cart + uniform rod (the model behind the equations of motion)."""
    _, dx, dth, th = state
    kin = 0.5 * (M + MP) * dx**2 + 0.5 * MP * L * np.cos(th) * dx * dth + MP * L**2 * dth**2 / 6
    return kin - MP * G * 0.5 * L * np.cos(th)


def test_cartpole_spaces_and_defaults():
    env = CartPoleSwingUp()
    assert env.action_space.shape == (1,) and env.action_space.dtype == np.float64
    assert env.action_space.low[0] == -10 and env.action_space.high[0] == 10
    assert env.observation_space.shape == (4,)
    assert env.dt == 0.1 and env.max_episode_steps == 40
    obs, info = env.reset(seed=0)
    assert obs.shape == (4,) and obs.dtype == np.float64
    assert env.state.shape == (4,)
    assert "tip_distance" in info


def test_cartpole_step_matches_direct_ode_solve():
    env = CartPoleSwingUp(noise_std=0.0)
    s0 = np.array([0.1, -0.3, 1.2, 0.7])
    env.reset(options={"state": s0})
    obs, *_ = env.step(np.array([3.7]))
    sol = solve_ivp(
        lambda t, y: reference_ode(y, 3.7), (0, 0.1), s0, method="RK45", rtol=1e-10, atol=1e-12
    )
    np.testing.assert_allclose(env.state, sol.y[:, -1], rtol=1e-6, atol=1e-8)
    np.testing.assert_array_equal(obs, env.state)  # no noise
    np.testing.assert_allclose(env.state_derivative(s0, 3.7), reference_ode(s0, 3.7))


def test_cartpole_free_pendulum_oscillates_and_conserves_energy():
    env = CartPoleSwingUp(friction=0.0, noise_std=0.0, max_episode_steps=None)
    s0 = np.array([0.0, 0.0, 0.0, 0.3])
    env.reset(options={"state": s0})
    e0 = energy(s0)
    thetas = [s0[3]]
    for _ in range(30):
        env.step([0.0])
        thetas.append(env.state[3])
        assert energy(env.state) == pytest.approx(e0, abs=1e-6)
    thetas = np.array(thetas)
    assert thetas.min() < -0.25 and thetas.max() <= 0.3 + 1e-6  # swings to the other side
    assert np.sum(np.diff(np.sign(thetas)) != 0) >= 4  # several zero crossings
    # Momentum (M+m) x_dot + m l/2 cos(th) th_dot is conserved without friction/force.
    _, dx, dth, th = env.state
    assert (M + MP) * dx + 0.5 * MP * L * np.cos(th) * dth == pytest.approx(0.0, abs=1e-7)


def test_cartpole_friction_dissipates_energy():
    env = CartPoleSwingUp(friction=0.5, noise_std=0.0)
    s0 = np.array([0.0, 1.0, 0.0, 0.5])
    env.reset(options={"state": s0})
    for _ in range(20):
        env.step([0.0])
    assert energy(env.state) < energy(s0) - 1e-3


def test_cartpole_force_is_clipped():
    a = CartPoleSwingUp(noise_std=0.0)
    b = CartPoleSwingUp(noise_std=0.0)
    s0 = np.array([0.0, 0.0, 0.0, 0.2])
    a.reset(options={"state": s0})
    b.reset(options={"state": s0})
    _, _, _, _, info = a.step([100.0])
    b.step(np.array([10.0]))
    assert info["force"] == 10.0
    np.testing.assert_array_equal(a.state, b.state)
    a.step(-55.0)  # scalar action also accepted, clipped to -10
    b.step([-10.0])
    np.testing.assert_array_equal(a.state, b.state)
    assert a.state[1] != 0.0


def test_cartpole_seed_reproducibility_and_noise():
    actions = np.linspace(-10, 10, 15)

    def run(seed):
        env = CartPoleSwingUp()
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for u in actions:
            out.append(env.step([u])[0])
        return np.array(out), env.state.copy()

    o1, s1 = run(7)
    o2, s2 = run(7)
    o3, _ = run(8)
    np.testing.assert_array_equal(o1, o2)
    np.testing.assert_array_equal(s1, s2)
    assert not np.allclose(o1, o3)

    env = CartPoleSwingUp()
    env.reset(seed=0)
    diffs = []
    for _ in range(40):
        obs, _, _, _, info = env.step([0.0])
        diffs.append(obs - info["state"])
    diffs = np.array(diffs)
    assert 0.005 < diffs.std() < 0.02  # measurement noise std 0.01 on the observation only


def test_cartpole_start_distribution():
    env = CartPoleSwingUp()
    starts = np.array([env.reset(seed=i)[1]["state"] for i in range(300)])
    assert np.all(np.abs(starts.mean(0)) < 0.03)
    np.testing.assert_allclose(starts.std(0), 0.1, rtol=0.2)


def test_cartpole_reward_and_tip_distance():
    env = CartPoleSwingUp(noise_std=0.0)
    assert env.tip_distance([0, 0, 0, np.pi]) == pytest.approx(0.0, abs=1e-12)
    assert env.tip_distance([0, 0, 0, 0.0]) == pytest.approx(2 * L)
    assert env.tip_distance([0.3, 0, 0, np.pi]) == pytest.approx(0.3)
    assert env.tip_distance([1.0, 0, 0, np.pi / 2]) == pytest.approx(np.hypot(1.5, 0.5))
    env.reset(options={"state": [0.0, 0.0, 0.0, np.pi]})
    _, r, term, trunc, info = env.step([0.0])  # upright is an (unstable) equilibrium
    assert r == pytest.approx(0.0, abs=1e-9) and info["tip_distance"] < 1e-6
    assert not term and not trunc
    env.reset(options={"state": [0.0, 0.0, 0.0, 0.0]})
    _, r, *_ = env.step([0.0])
    assert r == pytest.approx(-(1 - np.exp(-1.0 / (2 * 0.25**2))))
    d = 0.2
    assert env.cost([d, 0, 0, np.pi]) == pytest.approx(1 - np.exp(-(d**2) / (2 * 0.25**2)))


def test_cartpole_horizon_and_registered_make():
    env = gymnasium.make(CARTPOLE_ID)
    assert env.spec.max_episode_steps == 40
    env.reset(seed=1)
    for t in range(40):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        assert not term
        assert trunc == (t == 39)
    direct = CartPoleSwingUp()
    direct.reset(seed=0)
    truncs = [direct.step([0.0])[3] for _ in range(40)]
    assert truncs[-1] and not any(truncs[:-1])


def test_cartpole_render():
    env = CartPoleSwingUp(render_mode="rgb_array")
    env.reset(seed=0, options={"state": [0.0, 0.0, 0.0, 0.0]})
    img = env.render()
    assert img.shape == (400, 600, 3) and img.dtype == np.uint8
    assert len(np.unique(img.reshape(-1, 3), axis=0)) >= 4  # background, rail, cart, pole...
    env.reset(options={"state": [1.0, 0.0, 0.0, np.pi]})
    img2 = env.render()
    assert np.any(img != img2)
    assert CartPoleSwingUp().render() is None  # no render_mode


@pytest.mark.filterwarnings("ignore:.*(infinity|symmetric and normalized).*:UserWarning")
def test_cartpole_passes_gymnasium_checker():
    check_env(CartPoleSwingUp(), skip_render_check=True)


def test_cartpole_bad_input():
    env = CartPoleSwingUp()
    with pytest.raises(RuntimeError):
        env.step([0.0])
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step([1.0, 2.0])
    with pytest.raises(ValueError, match="finite"):
        env.step([np.nan])
    with pytest.raises(ValueError, match="state"):
        env.reset(options={"state": [0.0, 1.0]})
    with pytest.raises(ValueError, match="Unknown reset options"):
        env.reset(options={"sate": [0, 0, 0, 0]})
    with pytest.raises(ValueError, match="cart_mass"):
        CartPoleSwingUp(cart_mass=-1.0)
    with pytest.raises(TypeError, match="pole_length"):
        CartPoleSwingUp(pole_length="long")
    with pytest.raises(ValueError, match="render_mode"):
        CartPoleSwingUp(render_mode="human")


# ---------------------------------------------------------------------------
# Fetch joint reacher
# ---------------------------------------------------------------------------

START = np.array([0.0, -1.0, 0.0, 2.0, 0.0, 0.5, 0.0])
# Found offline by random search + hill climbing with elbow_flex = 0 (rolls at 0). The
# env is purely kinematic: this pose puts the wrist through the table (no collisions).
DAMAGED_REACH_POSE = np.array([-0.653, 1.199, 0.0, 0.0, 0.0, -1.95, 0.0])
# Also found offline, penalising penetration: reaches without touching the table.
DAMAGED_REACH_POSE_FREE = np.array([-0.583, 0.205, -0.864, 0.0, -2.421, -1.95, 2.771])
ELBOW = 3


@pytest.fixture(scope="module")
def fetch_cls():
    # pilco.envs.fetch_reacher already chose MUJOCO_GL=egl (headless) before mujoco loads.
    try:
        pytest.importorskip("mujoco")
    except pytest.skip.Exception:
        raise
    except Exception as exc:  # a broken GL backend fails at import time
        pytest.skip(f"mujoco cannot be imported here: {exc!r}")
    from pilco.envs.fetch_reacher import FetchJointReacher, default_model_path

    try:
        default_model_path()
    except (ImportError, FileNotFoundError) as exc:
        pytest.skip(f"gymnasium-robotics Fetch model unavailable: {exc}")

    return FetchJointReacher


def test_fetch_start_pose_and_spaces(fetch_cls):
    env = fetch_cls()
    obs, info = env.reset(seed=0)
    assert obs.shape == (10,) and obs.dtype == np.float64
    assert env.observation_space.contains(obs)
    assert env.action_space.shape == (7,)
    np.testing.assert_allclose(env.action_space.high, 0.1)
    np.testing.assert_allclose(obs[3:], START)
    # Paper / FetchReach value (1.228, 0.744, 0.489); ours has the torso lift at exactly 0
    # (FetchReach's physics warm-up lets it drift to 1.3 mm), hence z = 0.4876.
    np.testing.assert_allclose(obs[:3], [1.228, 0.744, 0.489], atol=0.01)
    np.testing.assert_allclose(obs[:3], [1.2283, 0.7441, 0.4876], atol=1e-3)
    np.testing.assert_allclose(env.target, [1.2, 0.38, 0.38])
    assert info["distance"] == pytest.approx(np.linalg.norm(obs[:3] - env.target))
    assert not info["is_success"]


def test_fetch_joint_limits_from_model(fetch_cls):
    env = fetch_cls()
    lim = env.joint_limits
    np.testing.assert_allclose(lim[0], [-1.6056, 1.6056])
    np.testing.assert_allclose(lim[1], [-1.221, 1.518])
    np.testing.assert_allclose(lim[3], [-2.251, 2.251])
    np.testing.assert_allclose(lim[5], [-2.16, 2.16])
    assert np.all(np.isinf(lim[[2, 4, 6]]))  # roll joints are continuous


def test_fetch_action_moves_joints_by_clipped_amount(fetch_cls):
    env = fetch_cls()
    env.reset(seed=0)
    q0 = env.qpos
    a = np.array([0.05, -0.3, 0.2, -0.01, 0.0, 1.0, -0.07])
    obs, reward, term, trunc, info = env.step(a)
    np.testing.assert_allclose(obs[3:] - q0, np.clip(a, -0.1, 0.1), atol=1e-12)
    np.testing.assert_allclose(obs[:3], env.ee_position)
    assert reward == pytest.approx(-np.linalg.norm(obs[:3] - env.target))
    assert reward == pytest.approx(-info["distance"])
    assert not term and not trunc
    # Forward kinematics changed the gripper position.
    assert np.linalg.norm(obs[:3] - np.array([1.2283, 0.7441, 0.4876])) > 0.01


def test_fetch_joint_limits_respected(fetch_cls):
    env = fetch_cls(max_episode_steps=None)
    env.reset(seed=0)
    a = np.array([0.1, 0.1, 0.1, 0.1, 0.0, -0.1, 0.1])
    for _ in range(40):
        obs, *_ = env.step(a)
    q = obs[3:]
    assert q[0] == pytest.approx(1.6056)  # pan saturates at its upper limit
    assert q[1] == pytest.approx(1.518)
    assert q[3] == pytest.approx(2.251)
    assert q[5] == pytest.approx(-2.16)
    assert q[2] == pytest.approx(4.0) and q[6] == pytest.approx(4.0)  # unlimited rolls


def test_fetch_terminates_within_threshold(fetch_cls):
    env = fetch_cls()
    _, info = env.reset(seed=0)
    assert not info["is_success"]
    ee = env.ee_position
    env.reset(options={"target": ee + np.array([0.0, 0.0, 0.03])})
    _, reward, term, trunc, info = env.step(np.zeros(7))
    assert term and info["is_success"] and not trunc
    assert reward == pytest.approx(-0.03, abs=1e-9)
    env.target = ee + np.array([0.0, 0.06, 0.0])  # just outside the 5 cm ball
    _, _, term, _, info = env.step(np.zeros(7))
    assert not term and info["distance"] == pytest.approx(0.06)


def test_fetch_damaged_default_is_stuck_at_the_start_angle(fetch_cls):
    env = gymnasium.make(FETCH_DAMAGED_ID)
    healthy = gymnasium.make(FETCH_ID)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs, healthy.reset(seed=0)[0])  # the healthy start pose
    assert obs[3 + ELBOW] == START[ELBOW]
    rng = np.random.default_rng(0)
    for _ in range(8):  # any command, within the bound or beyond it
        obs, _, _, _, info = env.step(rng.uniform(-0.5, 0.5, 7))
        assert obs[3 + ELBOW] == START[ELBOW] and info["qpos"][ELBOW] == START[ELBOW]
        np.testing.assert_allclose(obs[:3], env.unwrapped.forward_kinematics(info["qpos"]),
                                   atol=1e-12)
    assert np.all(np.abs(np.delete(obs[3:], ELBOW) - np.delete(START, ELBOW)) > 1e-3)
    env.close()
    healthy.close()


def test_fetch_damaged_straight_mode(fetch_cls):
    env = gymnasium.make(FETCH_DAMAGED_ID, damage_mode="straight")
    obs, _ = env.reset(seed=0)
    assert obs[3 + ELBOW] == 0.0
    np.testing.assert_allclose(np.delete(obs[3:], ELBOW), np.delete(START, ELBOW))
    assert env.unwrapped.damaged_joints == ("elbow_flex",)
    for _ in range(5):
        obs, *_ = env.step(np.full(7, 0.1))
        assert obs[3 + ELBOW] == 0.0
    np.testing.assert_allclose(obs[3], 0.5)  # shoulder_pan still moves
    env.close()


def test_fetch_damaged_pose_reaches_default_target(fetch_cls):
    env = fetch_cls(damaged_joints=("elbow_flex",), damage_mode="straight")
    _, info = env.reset(options={"qpos": DAMAGED_REACH_POSE})
    assert info["qpos"][ELBOW] == 0.0
    assert info["distance"] < 0.005  # reachable without the elbow: found 0.4 mm
    assert info["is_success"]
    _, info = env.reset(options={"qpos": DAMAGED_REACH_POSE_FREE})
    assert info["distance"] < 0.005  # 1.4 mm, collision free


def test_fetch_stuck_mode_and_runtime_damage(fetch_cls):
    env = fetch_cls(damaged_joints=("robot0:elbow_flex_joint",), damage_mode="stuck")
    env.reset(seed=0)
    for _ in range(3):
        obs, *_ = env.step(np.full(7, -0.1))
    assert obs[3 + ELBOW] == pytest.approx(2.0)  # held at its start angle

    env = fetch_cls()
    env.reset(seed=0)
    env.step(np.full(7, 0.05))
    env.damage("wrist_flex", mode="stuck")
    held = env.qpos[5]
    for _ in range(3):
        obs, *_ = env.step(np.full(7, 0.05))
    assert obs[3 + 5] == held and obs[3 + ELBOW] == pytest.approx(2.2)
    env.damage(("elbow_flex",), mode="straight")  # replaces the previous damage
    obs, *_ = env.step(np.full(7, 0.05))
    assert obs[3 + ELBOW] == 0.0 and obs[3 + 5] == pytest.approx(held + 0.05)
    env.repair()
    obs, *_ = env.step(np.full(7, 0.05))
    assert obs[3 + ELBOW] == pytest.approx(0.05)
    assert env.damaged_joints == ()


def test_damage_flag_tells_when_the_arm_broke(fetch_cls):
    env = penvs.DamageFlag(fetch_cls())
    assert env.observation_space.shape == (11,)
    obs, _ = env.reset(seed=0)
    plain = env.unwrapped._obs()
    np.testing.assert_array_equal(obs, np.append(plain, 0.0))
    assert env.observation_space.contains(obs)
    obs, *_ = env.step(np.full(7, 0.05))
    assert obs[-1] == 0.0
    env.unwrapped.damage("elbow_flex", mode="stuck")
    obs, *_ = env.step(np.full(7, 0.05))
    assert obs[-1] == 1.0 and obs.shape == (11,)
    assert env.reset(seed=1)[0][-1] == 1.0
    env.unwrapped.repair()
    assert env.reset(seed=1)[0][-1] == 0.0
    with pytest.raises(TypeError, match="Fetch reacher"):
        penvs.DamageFlag(CartPoleSwingUp())


def test_fetch_unknown_joint_and_bad_input(fetch_cls):
    with pytest.raises(ValueError, match="elbow_flex"):  # message lists valid names
        fetch_cls(damaged_joints=("knee",))
    with pytest.raises(ValueError, match="damage_mode"):
        fetch_cls(damage_mode="broken")
    with pytest.raises(ValueError, match="start_qpos"):
        fetch_cls(start_qpos=[0.0, 1.0])
    env = fetch_cls()
    with pytest.raises(ValueError, match="valid short names"):
        env.damage(("elbow",))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(4))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(7, np.inf))


def test_fetch_seeded_start_noise(fetch_cls):
    env = fetch_cls(start_noise=0.05)
    o1, _ = env.reset(seed=3)
    o2, _ = env.reset(seed=3)
    o3, _ = env.reset(seed=4)
    np.testing.assert_array_equal(o1, o2)
    assert not np.allclose(o1, o3)
    assert 0.0 < np.abs(o1[3:] - START).max() < 0.3


def test_fetch_registered_ids_and_horizon(fetch_cls):
    env = gymnasium.make(FETCH_ID)
    assert env.spec.max_episode_steps == 50
    obs, _ = env.reset(seed=0)
    assert obs.shape == (10,)
    for t in range(50):
        _, _, term, trunc, _ = env.step(np.zeros(7))
        assert not term
        assert trunc == (t == 49)
    env.close()
    assert gymnasium.make(FETCH_DAMAGED_ID).spec.max_episode_steps == 50


def test_fetch_forward_kinematics_restores_state(fetch_cls):
    env = fetch_cls()
    env.reset(seed=0)
    ee, q = env.ee_position, env.qpos
    ee_damaged = env.forward_kinematics(DAMAGED_REACH_POSE)
    np.testing.assert_allclose(ee_damaged, env.target, atol=0.005)
    np.testing.assert_array_equal(env.ee_position, ee)
    np.testing.assert_array_equal(env.qpos, q)


@pytest.mark.filterwarnings("ignore:.*(infinity|symmetric and normalized).*:UserWarning")
def test_fetch_passes_gymnasium_checker(fetch_cls):
    check_env(fetch_cls(start_noise=0.01), skip_render_check=True)


_RENDER_SCRIPT = r"""
import sys
import numpy as np
from pilco.envs.fetch_reacher import FetchJointReacher
env = FetchJointReacher(render_mode="rgb_array")
env.reset(seed=0)
try:
    img = env.render()
except Exception as exc:  # GL backends fail in many different ways
    print("NOGL", repr(exc))
    sys.exit(0)
env.step(np.full(7, 0.1))
img2 = env.render()
env.close()
np.savez(sys.argv[1], img=img, img2=img2)
print("OK")
"""


def test_fetch_render(fetch_cls, tmp_path):
    # MuJoCo's EGL renderer and TensorFlow crash in one process on this stack, and the
    # test session imports TensorFlow elsewhere: render in a fresh process (as the
    # examples do) and check the frames here.
    out = tmp_path / "frames.npz"
    proc = subprocess.run([sys.executable, "-c", _RENDER_SCRIPT, str(out)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    if "NOGL" in proc.stdout:
        pytest.skip(f"cannot create an offscreen MuJoCo GL context (MUJOCO_GL=egl): "
                    f"{proc.stdout.strip()}")
    frames = np.load(out)
    img, img2 = frames["img"], frames["img2"]
    assert img.shape == (480, 640, 3) and img.dtype == np.uint8
    assert img.std() > 10 and len(np.unique(img.reshape(-1, 3), axis=0)) > 50
    red = (img[..., 0] > 150) & (img[..., 1] < 60) & (img[..., 2] < 60)
    assert red.sum() > 5  # the red target marker is visible
    assert np.any(img2 != img)  # the arm moved


# ---------------------------------------------------------------------------
# Pendulum swing-up (gymnasium's Pendulum-v1, the reference port's workload)
# ---------------------------------------------------------------------------


def test_pendulum_starts_hanging_down_and_holds_each_action_for_three_steps():
    env = penvs.PendulumSwingUp()
    obs, info = env.reset(seed=3)
    assert obs.shape == (3,) and obs.dtype == np.float32
    assert obs[0] < -0.99 and abs(obs[2]) < 0.3  # cos θ ≈ -1: hanging, nearly at rest
    assert info["distance"] == pytest.approx(abs(info["theta"])) and info["distance"] > 2.9
    np.testing.assert_array_equal(env.reset(seed=3)[0], obs)  # seeded start

    reference = gymnasium.make("Pendulum-v1").unwrapped  # the same physics, step by step
    reference.reset(seed=0)
    reference.state = env.pendulum.state.copy()
    total = 0.0
    for _ in range(3):
        expected, r, *_ = reference.step(np.array([1.5], dtype=np.float32))
        total += r
    obs, reward, terminated, truncated, info = env.step([1.5])
    np.testing.assert_allclose(obs, expected, rtol=1e-6)
    assert reward == pytest.approx(total) and not terminated and not truncated
    theta = np.arctan2(obs[1], obs[0])
    assert info["theta"] == pytest.approx(theta, abs=1e-5)


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized.*:UserWarning")
def test_pendulum_registered_make_checker_and_render():
    env = gymnasium.make(penvs.PENDULUM_ID)
    assert env.spec.max_episode_steps == 40
    env.reset(seed=1)
    truncs = [env.step(env.action_space.sample())[3] for _ in range(40)]
    assert truncs[-1] and not any(truncs[:-1])
    check_env(penvs.PendulumSwingUp(), skip_render_check=True)
    drawn = penvs.PendulumSwingUp(render_mode="rgb_array")
    drawn.reset(seed=0)
    img = drawn.render()
    assert img.shape == (300, 300, 3) and img.dtype == np.uint8
    drawn.pendulum.state = np.array([0.0, 0.0])  # upright
    assert np.any(drawn.render() != img)
    assert penvs.PendulumSwingUp().render() is None


def test_pendulum_bad_input():
    env = penvs.PendulumSwingUp()
    with pytest.raises(RuntimeError, match="reset"):
        env.step([0.0])
    env.reset(seed=0)
    with pytest.raises(ValueError, match="torque"):
        env.step([1.0, 2.0])
    with pytest.raises(ValueError, match="torque"):
        env.step([np.nan])
    with pytest.raises(ValueError, match="Unknown reset options"):
        env.reset(options={"state": [0.0, 0.0]})
    with pytest.raises(ValueError, match="substeps"):
        penvs.PendulumSwingUp(substeps=0)
    with pytest.raises(ValueError, match="start_std"):
        penvs.PendulumSwingUp(start_std=-1.0)
