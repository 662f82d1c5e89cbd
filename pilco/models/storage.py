"""How each component of an agent is stored as named arrays, and read back.

The layout of agent files (``format: "pilco-agent"``) and policy files
(``format: "pilco-policy"``), both a single ``.npz`` (a zip of ``.npy`` arrays read with
``allow_pickle=False``: no code objects are ever stored) holding a JSON metadata string
under the key ``__meta__``. Every trainable quantity is stored twice: its value and its
raw, unconstrained variable, so a reloaded agent computes bit-identical predictions.

There is one way to save an agent: ``agent.save(path)`` and ``PILCO.load(path)``
(:class:`pilco.models.PILCO`), which the run directory's ``agent.npz`` uses
(:class:`pilco.experiment.RunStore`); :func:`save_agent` and :func:`load_agent` are the
bodies of those methods. A policy file is a different thing: the policy alone, evaluated
on a robot with NumPy by :func:`pilco.deploy.load_policy`; ``agent.export_policy(path)``
writes it, and :func:`export_policy` also writes one for a controller used without an
agent.

This module works on the public attributes of the components (controllers, rewards,
dynamics models) and of the agent.
"""
from __future__ import annotations

import inspect
import json
import logging
from typing import Any, Dict, List, Sequence, Tuple

import gpflow
import numpy as np

from .. import __version__, moments
from ..controllers import LinearController, RbfController, StartDraw, squash_sat, squash_sin
from ..deploy import META_KEY, POLICY_FORMAT, POLICY_VERSION, read_npz
from ..files import write_npz_atomic
from ..rewards import (AxisBumpsReward, CartPoleReward, CombinedRewards, ExponentialReward,
                       LinearMapReward, LinearReward)
from ..validation import check_format_version, check_path
from .custom import CUSTOM, build_custom, custom_spec
from .mgpr import MGPR
from .smgpr import SMGPR

__all__ = ["AGENT_FORMAT", "AGENT_VERSION", "POLICY_FORMAT", "agent_arrays", "read_agent",
           "restore_dynamics", "policy_arrays", "save_agent", "load_agent", "export_policy"]

logger = logging.getLogger(__name__)

AGENT_FORMAT = "pilco-agent"
#: newest agent format: 2 adds context dimensions, the index sets the dynamics model and
#: the policy read, and several start distributions (tasks). An agent using none of them
#: is written as version 1, readable by every version of pilco.
AGENT_VERSION = 2

_SQUASHES = {"squash_sin": squash_sin, "squash_sat": squash_sat}
# Short names used in policy files (read by pilco.deploy).
_SQUASH_KIND = {None: "none", "squash_sin": "sin", "squash_sat": "sat"}


# -- files ----------------------------------------------------------------------------------
def _read_npz(path, expected_format: str):
    """Arrays and metadata of a file written by this module; clear errors otherwise."""
    path = check_path(path)
    arrays, meta = read_npz(path, expected_format)
    if meta.get("format") != expected_format:
        raise ValueError(f"{path} holds format {meta.get('format')!r}, expected "
                         f"{expected_format!r}")
    return arrays, meta


def _get(arrays: Dict[str, np.ndarray], key: str, path) -> np.ndarray:
    try:
        return arrays[key]
    except KeyError:
        raise ValueError(f"{path} is incomplete: entry {key!r} is missing") from None


# -- parameters -----------------------------------------------------------------------------
def _put_params(arrays, trainable, key: str, params: Sequence[gpflow.Parameter]) -> None:
    """Store a list of same-shaped parameters stacked: values and raw variables."""
    arrays[key] = np.stack([p.numpy() for p in params])
    arrays[key + "_raw"] = np.stack([p.unconstrained_variable.numpy() for p in params])
    trainable[key] = [bool(p.trainable) for p in params]


def _get_params(params: Sequence[gpflow.Parameter], arrays, trainable, key: str, path) -> None:
    values = _get(arrays, key, path)
    raw = arrays.get(key + "_raw")
    flags = trainable.get(key)
    if len(values) != len(params):
        raise ValueError(f"{path}: entry {key!r} holds {len(values)} values, expected "
                         f"{len(params)}")
    for i, p in enumerate(params):
        if raw is not None and raw[i].shape == tuple(p.unconstrained_variable.shape):
            # the exact stored variable: no round trip through the transform (a value on
            # its bound, such as a noise variance at its floor, would not survive one)
            p.unconstrained_variable.assign(raw[i])
        else:
            p.assign(values[i])
        if flags is not None:
            gpflow.set_trainable(p, bool(flags[i]))


def _custom_spec(obj, arrays, trainable, prefix: str, what: str) -> dict:
    """A controller or reward of another class (:mod:`pilco.models.custom`): its metadata,
    its parameters stored under ``PREFIXparam.PATH`` as every parameter is."""
    spec, params = custom_spec(obj, what)
    for name, p in params.items():
        _put_params(arrays, trainable, f"{prefix}param{name}", [p])
    return spec


def _build_custom(spec: dict, arrays, trainable, prefix: str, path, what: str):
    obj, params = build_custom(spec, path, what)
    for name in spec.get("params", []):
        _get_params([params[name]], arrays, trainable, f"{prefix}param{name}", path)
    return obj


# -- components -----------------------------------------------------------------------------
def _squash_name(squash):
    if squash is None:
        return None
    for name, fn in _SQUASHES.items():
        if squash is fn:
            return name
    raise TypeError(
        f"cannot save a controller with squash function {squash!r}: only squash_sin, "
        f"squash_sat or None can be stored"
    )


def _controller_spec(controller, arrays, trainable) -> dict:
    kind = type(controller)
    if kind is RbfController:
        spec = dict(type="RbfController", state_dim=controller.state_dim,
                    control_dim=controller.control_dim,
                    num_basis_functions=controller.num_basis_functions,
                    squash=_squash_name(controller.squash))
        _put_params(arrays, trainable, "controller/centers", [controller.centers])
        _put_params(arrays, trainable, "controller/targets", [controller.targets])
        _put_params(arrays, trainable, "controller/lengthscales",
                    [g.kernel.lengthscales for g in controller.models])
        _put_params(arrays, trainable, "controller/variance",
                    [g.kernel.variance for g in controller.models])
        _put_params(arrays, trainable, "controller/noise",
                    [g.likelihood.variance for g in controller.models])
        draw = controller.randomizer
        if isinstance(draw, StartDraw):
            spec["randomizer"] = draw.to_dict()
        elif draw is not None and getattr(controller, "_unsaved_randomizer", None) is not draw:
            # said once per randomizer: a run saves its agent every episode
            controller._unsaved_randomizer = draw
            logger.warning("the controller's randomizer %r is not a StartDraw and is not "
                           "saved: the loaded agent's restarts draw from N(0, I)", draw)
    elif kind is LinearController:
        spec = dict(type="LinearController", state_dim=controller.state_dim,
                    control_dim=controller.control_dim, squash=_squash_name(controller.squash))
        _put_params(arrays, trainable, "controller/W", [controller.W])
        _put_params(arrays, trainable, "controller/b", [controller.b])
    else:
        return _custom_spec(controller, arrays, trainable, "controller/", "controller")
    arrays["controller/max_action"] = np.asarray(controller.max_action, dtype=np.float64)
    return spec


def _build_controller(spec: dict, arrays, trainable, path):
    kind = spec.get("type")
    if kind == CUSTOM:
        return _build_custom(spec, arrays, trainable, "controller/", path, "controller")
    squash = spec.get("squash")
    if squash is not None and squash not in _SQUASHES:
        raise ValueError(f"{path}: unknown squash function {squash!r}")
    squash = None if squash is None else _SQUASHES[squash]
    max_action = _get(arrays, "controller/max_action", path)
    if kind == "RbfController":
        c = RbfController(spec["state_dim"], spec["control_dim"], spec["num_basis_functions"],
                          max_action=max_action, squash=squash)
        _get_params([c.centers], arrays, trainable, "controller/centers", path)
        _get_params([c.targets], arrays, trainable, "controller/targets", path)
        _get_params([g.kernel.lengthscales for g in c.models], arrays, trainable,
                    "controller/lengthscales", path)
        _get_params([g.kernel.variance for g in c.models], arrays, trainable,
                    "controller/variance", path)
        _get_params([g.likelihood.variance for g in c.models], arrays, trainable,
                    "controller/noise", path)
        if spec.get("randomizer") is not None:
            try:
                c.randomizer = StartDraw.from_dict(spec["randomizer"])
            except (TypeError, ValueError) as err:
                raise ValueError(f"{path}: bad controller randomizer ({err})") from err
    elif kind == "LinearController":
        c = LinearController(spec["state_dim"], spec["control_dim"], max_action=max_action,
                             squash=squash)
        _get_params([c.W], arrays, trainable, "controller/W", path)
        _get_params([c.b], arrays, trainable, "controller/b", path)
    else:
        raise ValueError(f"{path}: unknown controller type {kind!r}")
    return c


def _reward_spec(reward, arrays, trainable, prefix: str) -> dict:
    kind = type(reward)
    if kind is ExponentialReward:
        arrays[prefix + "W"] = reward.W.numpy()
        arrays[prefix + "t"] = reward.t.numpy()
        return dict(type="ExponentialReward", state_dim=reward.state_dim)
    if kind is AxisBumpsReward:
        for name in ("t", "widths", "coefs"):
            arrays[prefix + name] = getattr(reward, name).numpy()
        return dict(type="AxisBumpsReward", state_dim=reward.state_dim, dims=list(reward.dims))
    if kind is LinearReward:
        arrays[prefix + "W"] = reward.W.numpy()
        return dict(type="LinearReward", state_dim=reward.state_dim)
    if kind is CombinedRewards:
        arrays[prefix + "coefs"] = reward.coefs.numpy()
        parts = [_reward_spec(r, arrays, trainable, f"{prefix}{i}/")
                 for i, r in enumerate(reward.base_rewards)]
        return dict(type="CombinedRewards", state_dim=reward.state_dim, rewards=parts)
    if kind is CartPoleReward:
        return dict(type="CartPoleReward", pendulum_length=reward.pendulum_length,
                    width=reward.width)
    if kind is LinearMapReward:
        arrays[prefix + "A"] = reward.A.numpy()
        arrays[prefix + "b"] = reward.b.numpy()
        return dict(type="LinearMapReward", state_dim=reward.state_dim,
                    base=_reward_spec(reward.base_reward, arrays, trainable, prefix + "base/"))
    return _custom_spec(reward, arrays, trainable, prefix, "reward")


def _build_reward(spec: dict, arrays, trainable, prefix: str, path):
    kind = spec.get("type")
    if kind == CUSTOM:
        return _build_custom(spec, arrays, trainable, prefix, path, "reward")
    if kind == "ExponentialReward":
        return ExponentialReward(spec["state_dim"], W=_get(arrays, prefix + "W", path),
                                 t=_get(arrays, prefix + "t", path))
    if kind == "AxisBumpsReward":
        return AxisBumpsReward(spec["state_dim"], spec["dims"],
                               *(_get(arrays, prefix + name, path)
                                 for name in ("t", "widths", "coefs")))
    if kind == "LinearReward":
        return LinearReward(spec["state_dim"], W=_get(arrays, prefix + "W", path))
    if kind == "CombinedRewards":
        parts = [_build_reward(s, arrays, trainable, f"{prefix}{i}/", path)
                 for i, s in enumerate(spec["rewards"])]
        return CombinedRewards(spec["state_dim"], parts, coefs=_get(arrays, prefix + "coefs", path))
    if kind == "CartPoleReward":
        return CartPoleReward(pendulum_length=spec["pendulum_length"], width=spec["width"])
    if kind == "LinearMapReward":
        base = _build_reward(spec["base"], arrays, trainable, prefix + "base/", path)
        return LinearMapReward(spec["state_dim"], base, _get(arrays, prefix + "A", path),
                               _get(arrays, prefix + "b", path))
    raise ValueError(f"{path}: unknown reward type {kind!r}")


# Constructor settings of the dynamics model that are stored and restored.
_GP_SETTINGS = ("noise_floor", "max_snr", "max_lengthscale_ratio")


def _gp_params(gp):
    """The stored parameter lists of a dynamics model, by key."""
    out = {"gp/lengthscales": [m.kernel.lengthscales for m in gp.models],
           "gp/variance": [m.kernel.variance for m in gp.models],
           "gp/noise": [m.likelihood.variance for m in gp.models]}
    if isinstance(gp, SMGPR):
        out["gp/Z"] = [gp.inducing_variable.Z]
    return out


def _gp_spec(gp, arrays, trainable) -> dict:
    kind = type(gp)
    if kind not in (MGPR, SMGPR):
        raise TypeError(f"cannot save a dynamics model of type {kind.__name__}: supported "
                        f"are MGPR and SMGPR")
    for key, params in _gp_params(gp).items():
        _put_params(arrays, trainable, key, params)
    spec = dict(type=kind.__name__)
    spec.update({k: float(getattr(gp, k)) for k in _GP_SETTINGS if hasattr(gp, k)})
    if kind is SMGPR:
        spec["num_induced_points"] = gp.num_induced_points
    return spec


def restore_dynamics(gp, arrays, trainable, path) -> None:
    """Assign the stored hyperparameters (and inducing inputs) to the dynamics model, and
    its transitions' noise factors if stored (files without them: all ones)."""
    for key, params in _gp_params(gp).items():
        _get_params(params, arrays, trainable, key, path)
    if "data/noise_scales" in arrays:
        gp.set_noise_scales(arrays["data/noise_scales"])


# -- agents ---------------------------------------------------------------------------------
def agent_arrays(agent) -> Dict[str, np.ndarray]:
    """Everything :func:`read_agent` needs to rebuild ``agent``, as named arrays.

    Stored: raw data ``X [N, D + U]``, ``Y [N, D]`` and their noise factors ``[N]``; GP
    hyperparameters (lengthscales [E, Fd + U], signal and noise variances [E], inducing
    inputs Z [M, Fd + U] for a sparse model) and settings; controller type, settings and
    parameters; reward type and parameters; horizon, ``m_init`` [1, D],
    ``S_init`` [D, D], angle indices, ``num_induced_points`` and ``policy_input_noise``;
    in version 2 also ``m_init`` [T, D] with ``S_init`` [D, D] or [T, D, D] (T tasks)
    and the non-default index sets (``context_indices``, ``dynamics_indices``,
    ``policy_indices``).
    Controllers and rewards of other classes are stored through their ``get_config()``
    (:mod:`pilco.models.custom`). Raises :class:`TypeError` for components that cannot be
    stored (controllers or rewards without ``get_config()``, squash functions, dynamics
    models of other classes).
    """
    arrays: Dict[str, np.ndarray] = {}
    trainable: Dict[str, List[bool]] = {}
    X, Y = agent.data
    arrays["data/X"], arrays["data/Y"] = X, Y
    arrays["data/noise_scales"] = agent.mgpr.noise_scales
    arrays["m_init"] = agent.m_init
    arrays["S_init"] = agent.S_init
    layout = agent.layout.settings()  # the index sets that differ from their defaults
    version = 2 if layout or agent.num_tasks > 1 else 1
    meta = dict(
        format=AGENT_FORMAT, version=version, pilco_version=__version__,
        state_dim=agent.state_dim, control_dim=agent.control_dim, horizon=agent.horizon,
        angle_indices=list(agent.angle_indices),
        num_induced_points=(None if agent.num_induced_points is None
                            else int(agent.num_induced_points)),
        policy_input_noise=bool(agent.policy_input_noise),
        controller=_controller_spec(agent.controller, arrays, trainable),
        reward=_reward_spec(agent.reward, arrays, trainable, "reward/"),
        gp=_gp_spec(agent.mgpr, arrays, trainable),
        trainable=trainable,
        **layout,
    )
    arrays[META_KEY] = np.array(json.dumps(meta))
    return arrays


def read_agent(path) -> Tuple[Dict[str, Any], Any]:
    """Read an agent file: the ``PILCO`` constructor's keyword arguments, and a function
    that assigns the stored dynamics-model values to the rebuilt agent's ``mgpr``."""
    arrays, meta = _read_npz(path, AGENT_FORMAT)
    check_format_version(meta, path, "agent", AGENT_VERSION, f"this pilco ({__version__})")
    trainable = meta.get("trainable", {})
    spec = meta["gp"]
    if spec.get("type") not in ("MGPR", "SMGPR"):
        raise ValueError(f"{path}: unknown dynamics model type {spec.get('type')!r}")
    accepted = inspect.signature(MGPR.__init__).parameters
    kwargs = dict(
        data=(_get(arrays, "data/X", path), _get(arrays, "data/Y", path)),
        controller=_build_controller(meta["controller"], arrays, trainable, path),
        reward=_build_reward(meta["reward"], arrays, trainable, "reward/", path),
        horizon=meta["horizon"], m_init=_get(arrays, "m_init", path),
        S_init=_get(arrays, "S_init", path), angle_indices=meta["angle_indices"],
        num_induced_points=meta["num_induced_points"],
        policy_input_noise=meta["policy_input_noise"],
        model_options={k: float(spec[k]) for k in _GP_SETTINGS if k in spec and k in accepted},
        **{k: meta[k] for k in ("context_indices", "dynamics_indices", "policy_indices")
           if k in meta},
    )
    return kwargs, lambda gp: restore_dynamics(gp, arrays, trainable, path)


# -- policies -------------------------------------------------------------------------------
def _deterministic_jitter() -> float:
    """Variance that moment matching adds to a deterministic GP's output (the RBF policy)."""
    return float(inspect.signature(moments.moment_match).parameters["deterministic_jitter"].default)


def policy_arrays(controller, state_dim: int,
                  angle_indices: Sequence[int]) -> Dict[str, np.ndarray]:
    """The policy file of ``controller`` as named arrays.

    The file holds, as arrays: ``state_dim``, ``angle_indices`` [A], ``max_action`` [U],
    ``unsquashed_variance`` (the variance of the unsquashed action at a known state: the
    RBF policy's moment-matching jitter, 0 for the linear policy), and for an RBF policy
    ``centers`` [n, F], ``beta`` [U, n] (``(K + noise I)^-1 targets`` per output),
    ``targets`` [n, U], ``lengthscales`` [U, F], ``variance`` [U], ``noise`` [U]; for a
    linear policy ``W`` [U, F] and ``b`` [1, U]. ``F = D + A``: the policy reads the state
    with each angle replaced by (sin, cos), appended after the other dimensions. The JSON
    metadata names the controller kind (``rbf``/``linear``) and squash (``sin``/``sat``/
    ``none``).
    """
    angle_indices = [int(a) for a in angle_indices]
    squash = _SQUASH_KIND[_squash_name(controller.squash)]
    arrays: Dict[str, np.ndarray] = dict(
        state_dim=np.array(state_dim, dtype=np.int64),
        angle_indices=np.array(angle_indices, dtype=np.int64).reshape(-1),
        max_action=np.asarray(controller.max_action, dtype=np.float64).reshape(-1),
    )
    if type(controller) is RbfController:
        kind = "rbf"
        fact = controller.factorize()
        ell, sf2, sn2 = (t.numpy() for t in controller.hyperparameters())
        arrays.update(
            centers=controller.centers.numpy(), targets=controller.targets.numpy(),
            beta=fact.beta.numpy(), lengthscales=ell, variance=sf2, noise=sn2,
            unsquashed_variance=np.array(_deterministic_jitter()),
        )
        if not np.all(np.isfinite(arrays["beta"])):
            raise ValueError("the policy's weights (beta) are not finite; cannot export")
    elif type(controller) is LinearController:
        kind = "linear"
        arrays.update(W=controller.W.numpy(), b=controller.b.numpy(),
                      unsquashed_variance=np.array(0.0))
    else:
        raise TypeError(f"cannot export a controller of type {type(controller).__name__}: "
                        f"a policy file holds an RbfController or a LinearController, "
                        f"evaluated with NumPy alone; a controller of your own is saved "
                        f"with its agent (agent.save, PILCO.load)")
    meta = dict(format=POLICY_FORMAT, version=POLICY_VERSION, pilco_version=__version__,
                kind=kind, squash=squash, state_dim=state_dim,
                control_dim=controller.control_dim, feature_dim=controller.state_dim,
                angle_indices=angle_indices)
    arrays[META_KEY] = np.array(json.dumps(meta))
    return arrays


# -- files ----------------------------------------------------------------------------------
def save_agent(agent, path) -> str:
    """Write :func:`agent_arrays` of ``agent`` to ``path`` atomically; returns the path.
    The body of ``PILCO.save``."""
    written = write_npz_atomic(check_path(path), agent_arrays(agent))
    logger.info("saved PILCO agent (%d transitions) to %s", len(agent.data[0]), written)
    return written


def load_agent(agent_class, path):
    """Rebuild the agent stored at ``path`` as an instance of ``agent_class`` (PILCO).
    The body of ``PILCO.load``."""
    try:
        kwargs, restore = read_agent(path)
    except KeyError as err:  # a metadata entry of the format is missing
        raise ValueError(f"{path} is incomplete: its metadata lack {err.args[0]!r}") from None
    agent = agent_class(**kwargs)
    restore(agent.mgpr)
    logger.info("loaded PILCO agent from %s", path)
    return agent


def export_policy(controller, path, state_dim: int, angle_indices: Sequence[int]) -> str:
    """Write :func:`policy_arrays` to ``path`` atomically; returns the path written.

    The body of ``PILCO.export_policy``; for a controller used without an agent, pass
    the measured state's size ``state_dim`` and its ``angle_indices`` (each read by the
    controller as a (sin, cos) pair), e.g. ``export_policy(controller, path,
    controller.state_dim, [])`` for a controller that reads the state as it is."""
    written = write_npz_atomic(check_path(path),
                               policy_arrays(controller, state_dim, angle_indices))
    logger.info("exported %s policy to %s", type(controller).__name__, written)
    return written
