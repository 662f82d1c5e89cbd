"""Exported policies (PILCO.export_policy, and storage.export_policy for a bare controller)
evaluated by pilco.deploy with NumPy."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from pilco.controllers import LinearController, RbfController, squash_sat, squash_sin
from pilco.deploy import Policy, load_policy
from pilco.models import PILCO, storage
from pilco.rewards import ExponentialReward

ROOT = Path(__file__).resolve().parents[1]
TOL = 1e-8


def make_agent(kind, squash, angles=(), D=3, U=1, seed=0):
    rng = np.random.default_rng(seed)
    F = D + len(angles)
    max_action = np.linspace(1.5, 2.5, U)
    if kind == "rbf":
        n = 8
        controller = RbfController(F, U, n, max_action=max_action, squash=squash, seed=seed)
        controller.set_data((rng.standard_normal((n, F)), rng.standard_normal((n, U))))
        for g in controller.models:
            g.kernel.lengthscales.assign(rng.uniform(0.5, 2.0, F))
    else:
        controller = LinearController(F, U, max_action=max_action, squash=squash, seed=seed)
        controller.W.assign(rng.standard_normal((U, F)))
        controller.b.assign(rng.standard_normal((1, U)))
    X = rng.standard_normal((20, D + U))
    Y = 0.1 * rng.standard_normal((20, D))
    return PILCO((X, Y), controller, ExponentialReward(D), horizon=5, angle_indices=angles)


CASES = {
    "rbf-sin": ("rbf", squash_sin, ()),
    "rbf-sat": ("rbf", squash_sat, ()),
    "rbf-sin-angles": ("rbf", squash_sin, (0, 2)),
    "rbf-sat-angles": ("rbf", squash_sat, (1,)),
    "rbf-none-angles": ("rbf", None, (1,)),
    "linear-sin": ("linear", squash_sin, ()),
    "linear-sat-angles": ("linear", squash_sat, (2,)),
    "linear-none": ("linear", None, ()),
}


@pytest.mark.parametrize("U", [1, 2])
@pytest.mark.parametrize("case", list(CASES))
def test_same_actions_as_compute_action(tmp_path, case, U):
    kind, squash, angles = CASES[case]
    agent = make_agent(kind, squash, angles, U=U)
    agent.export_policy(tmp_path / "policy.npz")
    policy = load_policy(tmp_path / "policy.npz")
    assert (policy.state_dim, policy.control_dim) == (3, U)
    states = 2.0 * np.random.default_rng(1).standard_normal((4, 3))
    expected = np.concatenate([agent.compute_action(x) for x in states])
    for x, u in zip(states, expected):
        got = policy(x)
        assert got.shape == (U,)
        np.testing.assert_allclose(got, u, rtol=0, atol=TOL)
    batch = policy(states)
    assert batch.shape == (4, U)
    np.testing.assert_allclose(batch, expected, rtol=0, atol=TOL)
    # lists work as well as arrays
    np.testing.assert_allclose(policy(states[0].tolist()), expected[0], rtol=0, atol=TOL)


def test_a_bare_controller_can_be_exported(tmp_path):
    controller = RbfController(2, 1, 5, max_action=3.0, seed=4)
    storage.export_policy(controller, tmp_path / "policy.npz", controller.state_dim, [])
    policy = load_policy(tmp_path / "policy.npz")
    x = np.array([0.3, -0.7])
    m, _, _ = controller.compute_action(x.reshape(1, -1), np.zeros((2, 2)))
    np.testing.assert_allclose(policy(x), m.numpy()[0], rtol=0, atol=TOL)


def test_policy_file_is_small_and_self_describing(tmp_path):
    agent = make_agent("rbf", squash_sat, (1,), U=2)
    agent.export_policy(tmp_path / "policy.npz")
    assert os.path.getsize(tmp_path / "policy.npz") < 20_000
    with np.load(tmp_path / "policy.npz", allow_pickle=False) as z:
        meta = json.loads(str(z["__meta__"]))
        assert meta["format"] == "pilco-policy"
        assert (meta["kind"], meta["squash"]) == ("rbf", "sat")
        assert z["centers"].shape == (8, 4) and z["beta"].shape == (2, 8)
        assert z["lengthscales"].shape == (2, 4) and z["variance"].shape == (2,)
        assert z["noise"].shape == (2,)
        np.testing.assert_array_equal(z["angle_indices"], [1])
        assert int(z["state_dim"]) == 3


def test_importing_deploy_does_not_import_tensorflow(tmp_path):
    """In a fresh process: import, load and evaluate with NumPy only."""
    agent = make_agent("rbf", squash_sin, (1,), U=2)
    agent.export_policy(tmp_path / "policy.npz")
    x = np.array([0.2, -1.0, 0.5])
    expected = agent.compute_action(x)[0]
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(ROOT)!r})
        import numpy as np
        import pilco
        from pilco.deploy import load_policy
        policy = load_policy({str(tmp_path / "policy.npz")!r})
        u = policy(np.array([0.2, -1.0, 0.5]))
        heavy = sorted(m for m in ("tensorflow", "gpflow", "tensorflow_probability")
                       if m in sys.modules)
        print(repr(heavy)); print(repr(u.tolist()))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    heavy, u = proc.stdout.strip().splitlines()[-2:]
    assert heavy == "[]"
    np.testing.assert_allclose(eval(u), expected, rtol=0, atol=TOL)


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    path = tmp_path_factory.mktemp("policy") / "policy.npz"
    make_agent("linear", squash_sin, (1,)).export_policy(path)
    return load_policy(path)


@pytest.mark.parametrize("state, error, match", [
    (np.zeros(4), ValueError, r"3 entries per row .* got shape \(4,\)"),
    (np.zeros((2, 2)), ValueError, r"3 entries per row .* got shape \(2, 2\)"),
    (np.zeros((1, 1, 3)), ValueError, r"must have shape \[3\] or \[N, 3\]"),
    (np.array([0.0, np.nan, 1.0]), ValueError, r"NaN or inf \(first at index \(1,\)\)"),
    (np.array([[0.0, 1.0, 1.0], [0.0, 1.0, np.inf]]), ValueError, r"NaN or inf .*\(1, 2\)"),
    ("0 1 2", TypeError, "array of numbers"),
    (["a", "b", "c"], TypeError, r"array of \(real\) numbers, got strings"),
    (None, TypeError, "array of numbers"),
])
def test_bad_states_are_rejected(policy, state, error, match):
    with pytest.raises(error, match=match):
        policy(state)


def test_bad_files_are_rejected(tmp_path):
    make_agent("linear", None).save(tmp_path / "agent.npz")
    with pytest.raises(ValueError, match="expected 'pilco-policy'.*PILCO.load"):
        load_policy(tmp_path / "agent.npz")
    np.savez(tmp_path / "other.npz", a=np.ones(3))
    with pytest.raises(ValueError, match="not a PILCO policy file"):
        load_policy(tmp_path / "other.npz")
    with pytest.raises(FileNotFoundError):
        load_policy(tmp_path / "missing.npz")


def _rewrite_meta(src, dst, **changes):
    """Copy the .npz ``src`` to ``dst`` with metadata fields changed (None: removed)."""
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["__meta__"]))
    meta.update(changes)
    meta = {k: v for k, v in meta.items() if v is not None}
    arrays["__meta__"] = np.array(json.dumps(meta))
    np.savez(dst, **arrays)
    return dst


def test_truncated_foreign_and_other_version_files_are_rejected(tmp_path):
    good = make_agent("rbf", squash_sin).export_policy(tmp_path / "policy.npz")
    content = Path(good).read_bytes()
    not_ours = "is not a PILCO policy file written by pilco"
    for size in (len(content) - 1, len(content) // 2, 10, 0):  # cut anywhere: never loaded
        (tmp_path / "cut.npz").write_bytes(content[:size])
        with pytest.raises(ValueError, match=not_ours + ": it is truncated or not an .npz"):
            load_policy(tmp_path / "cut.npz")
    (tmp_path / "text.npz").write_text("0.1 0.2 0.3\n")
    with pytest.raises(ValueError, match=not_ours + ": it is truncated or not an .npz"):
        load_policy(tmp_path / "text.npz")
    np.save(tmp_path / "array.npy", np.ones(3))
    with pytest.raises(ValueError, match=r"holds a single array \(.npy\), not an .npz"):
        load_policy(tmp_path / "array.npy")
    np.savez(tmp_path / "meta.npz", __meta__=np.array("{not json"), beta=np.ones(2))
    with pytest.raises(ValueError, match="'__meta__' entry is not a JSON object"):
        load_policy(tmp_path / "meta.npz")
    np.savez(tmp_path / "pickled.npz", __meta__=np.array([{"format": "pilco-policy"}]))
    with pytest.raises(ValueError, match=not_ours + ": its entries cannot be read"):
        load_policy(tmp_path / "pickled.npz")
    for version in (0, 2, "1", None, True):
        with pytest.raises(ValueError, match=f"policy format version {version!r}.*this "
                                             "reader reads policy format version 1"):
            load_policy(_rewrite_meta(good, tmp_path / "v.npz", version=version))
    # a file from another pilco release in the same format is read
    other = load_policy(_rewrite_meta(good, tmp_path / "old.npz", pilco_version="0.0.1"))
    np.testing.assert_array_equal(other(np.ones(3)), load_policy(good)(np.ones(3)))
    for path in (None, 3, b"policy.npz"):
        with pytest.raises(TypeError, match="path must be a file path"):
            load_policy(path)


def test_inconsistent_policy_arrays_are_rejected():
    common = dict(kind="rbf", squash="sin", state_dim=2, angle_indices=[], max_action=1.0)
    with pytest.raises(ValueError, match=r"centers must have shape \(3, 2\)"):
        Policy(centers=np.zeros((3, 5)), beta=np.zeros((1, 3)), lengthscales=np.ones((1, 2)),
               variance=np.ones(1), **common)
    with pytest.raises(ValueError, match="squash must be one of"):
        Policy(W=np.zeros((1, 2)), b=np.zeros(1), **dict(common, kind="linear", squash="tanh"))
    with pytest.raises(ValueError, match="angle_indices"):
        Policy(W=np.zeros((1, 3)), b=np.zeros(1), **dict(common, kind="linear",
                                                          angle_indices=[5]))
