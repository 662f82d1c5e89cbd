"""Figures of PILCO runs (matplotlib, Agg canvas; never opens a window).

- :func:`plot_distances`: distance to the target per step of every episode (paper
  Fig. 8, 10);
- :func:`plot_cost_prediction`: the cost per step the model predicted before an episode
  (mean ±2σ) against the cost the episode really had;
- :func:`plot_one_step`: one-step predictions of chosen state dimensions (mean ±2σ,
  observation noise included) against the real transitions, one row per episode
  (paper Fig. 9, 11);
- :func:`plot_multi_step`: the multi-step predicted trajectory (from the episode's start
  distribution, the policy of that episode) with its ±2σ band against the real one;
- :func:`save_frames`: the frames of an episode as a GIF (imageio) or a PNG strip;
- :func:`save_all`: every figure of a :class:`pilco.experiment.Experiment`.

The Fetch arm's renderer, ``replay_fetch_frames``, is
:func:`pilco.envs.fetch_render.replay_fetch_frames` (still importable from here).

The figures are built with ``matplotlib.figure.Figure`` and the Agg canvas directly, so
the global pyplot state and backend are left alone.
"""
from __future__ import annotations

import logging
import os
from typing import List, Optional, Sequence

import numpy as np

__all__ = [
    "plot_distances",
    "plot_cost_prediction",
    "plot_one_step",
    "plot_multi_step",
    "plot_targets",
    "save_frames",
    "save_all",
]

logger = logging.getLogger(__name__)


def _figure(width: float, height: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=100)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: str) -> str:
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.tight_layout()
    fig.savefig(path)
    logger.info("wrote %s", path)
    return path


def plot_distances(distances: Sequence[np.ndarray], path: str,
                   random: Optional[Sequence[bool]] = None, threshold: Optional[float] = None,
                   ylabel: str = "distance to target", title: str = "",
                   labels: Optional[Sequence[str]] = None,
                   marks: Optional[Sequence[int]] = None) -> str:
    """Distance per time step, one line per episode.

    Args:
        distances: per episode an array ``[T_i + 1]`` (index 0 the start state).
        path: PNG file to write.
        random: per episode, whether it was a random one (drawn dashed).
        threshold: horizontal line at the success distance.
        labels: legend entries (default "episode i").
        marks: episode numbers (1-based) after which a vertical marker is not drawn but
            the line is emphasised (e.g. the first episode after a damage).
    """
    fig = _figure(7, 4.2)
    ax = fig.add_subplot(1, 1, 1)
    n = len(distances)
    cmap = _colormap(n)
    for i, d in enumerate(distances):
        d = np.asarray(d, dtype=float)
        is_random = bool(random[i]) if random is not None else False
        label = labels[i] if labels is not None else (
            f"episode {i + 1}" + (" (random)" if is_random else ""))
        lw = 2.5 if marks is not None and (i + 1) in marks else 1.6
        ax.plot(np.arange(len(d)), d, "--" if is_random else "-", color=cmap(i), lw=lw,
                label=label)
    if threshold is not None:
        ax.axhline(threshold, color="k", ls=":", lw=1, label=f"threshold {threshold:g}")
    ax.set_xlabel("time step")
    ax.set_ylabel(ylabel)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=2 if n > 6 else 1)
    if title:
        ax.set_title(title)
    return _save(fig, path)


def plot_targets(training: Sequence[Sequence[float]], test: Sequence[Sequence[float]],
                 steps: Sequence[Optional[int]], path: str, within: int) -> str:
    """A multi-task run's targets in two projections (x-y from above, x-z from the side):
    the training targets as black crosses, each held-out test target as a dot coloured by
    the steps the final policy took to reach it (grey ring: not reached within
    ``within`` steps). ``training`` [T, 3], ``test`` [K, 3], ``steps`` [K] (None: not
    reached)."""
    train, tests = np.asarray(training, dtype=float), np.asarray(test, dtype=float)
    ok = np.array([n is not None and n <= within for n in steps], dtype=bool)
    fig = _figure(9, 4.2)
    for k, (i, j, name) in enumerate(((0, 1, "y [m]"), (0, 2, "z [m]"))):
        ax = fig.add_subplot(1, 2, k + 1)
        dots = ax.scatter(tests[ok, i], tests[ok, j], c=[steps[m] for m in np.flatnonzero(ok)],
                          cmap="viridis", vmin=0, vmax=within, s=40, label="test, reached")
        ax.scatter(tests[~ok, i], tests[~ok, j], facecolors="none", edgecolors="0.5", s=50,
                   label=f"test, not within {within} steps")
        ax.scatter(train[:, i], train[:, j], marker="x", color="k", s=60, label="training")
        ax.set_xlabel("x [m]")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
        if k == 0:
            ax.legend(fontsize=8)
        else:
            fig.colorbar(dots, ax=ax, label="steps to the target")
    fig.suptitle(f"held-out targets reached within {within} steps: {int(ok.sum())} of "
                 f"{len(tests)}")
    return _save(fig, path)


def _colormap(n: int):
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    return lambda i: cmap(0.85 * i / max(n - 1, 1))


def plot_cost_prediction(pred_cost: np.ndarray, pred_cost_var: np.ndarray,
                         real_cost: np.ndarray, path: str, title: str = "") -> str:
    """Predicted expected cost per step (mean ±2σ) against the real cost.

    Shapes: pred_cost [H+1], pred_cost_var [H+1] (index 0 the start), real_cost [T+1].
    """
    fig = _figure(7, 4)
    ax = fig.add_subplot(1, 1, 1)
    m = np.asarray(pred_cost, float)
    sd = np.sqrt(np.maximum(np.asarray(pred_cost_var, float), 0.0))
    t = np.arange(len(m))
    ax.fill_between(t, m - 2 * sd, m + 2 * sd, color="C0", alpha=0.25, label="predicted ±2σ")
    ax.plot(t, m, color="C0", lw=2, label="predicted expected cost")
    r = np.asarray(real_cost, float)
    ax.plot(np.arange(len(r)), r, "o-", color="C3", ms=3, lw=1.2, label="real cost")
    ax.set_xlabel("time step")
    ax.set_ylabel("cost")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title)
    return _save(fig, path)


def plot_one_step(episodes: Sequence[dict], dims: Sequence[int], names: Sequence[str],
                  path: str, title: str = "") -> str:
    """One-step predictions against the real next states, one row per episode.

    Each entry of ``episodes`` has ``"number"`` (int), ``"states"`` [T+1, D],
    ``"onestep_mean"`` [T, D] and ``"onestep_var"`` [T, D] (predicted state differences
    and their variance, noise included). The band is ``x_t + mean ± 2 sqrt(var)``.
    """
    rows = max(len(episodes), 1)
    fig = _figure(3.3 * len(dims), 2.3 * rows)
    for r, ep in enumerate(episodes):
        S = np.asarray(ep["states"], float)
        M = np.asarray(ep["onestep_mean"], float)
        V = np.asarray(ep["onestep_var"], float)
        T = len(M)
        t = np.arange(1, T + 1)
        for c, (d, name) in enumerate(zip(dims, names)):
            ax = fig.add_subplot(rows, len(dims), r * len(dims) + c + 1)
            mean = S[:T, d] + M[:, d]
            sd = np.sqrt(np.maximum(V[:, d], 0.0))
            ax.fill_between(t, mean - 2 * sd, mean + 2 * sd, color="C0", alpha=0.3,
                            label="±2σ")
            ax.plot(t, mean, color="C0", lw=1.5, label="predicted")
            ax.plot(t, S[1:T + 1, d], "x", color="C3", ms=4, label="real")
            ax.set_title(f"episode {ep['number']}: {name}", fontsize=9)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
            if r == rows - 1:
                ax.set_xlabel("time step", fontsize=8)
            if r == 0 and c == 0:
                ax.legend(fontsize=7)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def plot_multi_step(pred_mean: np.ndarray, pred_var: np.ndarray, states: np.ndarray,
                    dims: Sequence[int], names: Sequence[str], path: str,
                    title: str = "") -> str:
    """Multi-step predicted trajectory (mean ±2σ) against the real trajectory.

    Shapes: pred_mean [H+1, D], pred_var [H+1, D] (diagonal of the predicted state
    covariances), states [T+1, D].
    """
    fig = _figure(3.3 * len(dims), 3)
    M = np.asarray(pred_mean, float)
    sd = np.sqrt(np.maximum(np.asarray(pred_var, float), 0.0))
    S = np.asarray(states, float)
    t = np.arange(len(M))
    for c, (d, name) in enumerate(zip(dims, names)):
        ax = fig.add_subplot(1, len(dims), c + 1)
        ax.fill_between(t, M[:, d] - 2 * sd[:, d], M[:, d] + 2 * sd[:, d], color="C0",
                        alpha=0.3, label="predicted ±2σ")
        ax.plot(t, M[:, d], color="C0", lw=1.5, label="predicted")
        ax.plot(np.arange(len(S)), S[:, d], "o-", color="C3", ms=2.5, lw=1, label="real")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("time step", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        if c == 0:
            ax.legend(fontsize=7)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def save_frames(frames: Sequence[np.ndarray], path_base: str, fps: int = 10,
                strip_frames: int = 8) -> List[str]:
    """Write ``path_base + ".gif"`` (when imageio is available) and a PNG strip of up to
    ``strip_frames`` evenly spaced frames ``path_base + "_strip.png"``.

    ``frames``: RGB ``uint8`` arrays ``[H, W, 3]``. Returns the written paths.
    """
    frames = [np.asarray(f) for f in frames if f is not None]
    if not frames:
        return []
    written = []
    try:
        import imageio.v2 as imageio

        gif = path_base + ".gif"
        imageio.mimsave(gif, frames, duration=1.0 / fps, loop=0)
        written.append(gif)
    except Exception as err:  # the strip below is the fallback
        logger.info("no GIF (%s); writing a PNG strip only", err)
    idx = np.unique(np.linspace(0, len(frames) - 1, min(strip_frames, len(frames))).astype(int))
    h, w = frames[0].shape[:2]
    fig = _figure(min(2.2 * len(idx), 20), 2.2 * h / w + 0.3)
    for k, i in enumerate(idx):
        ax = fig.add_subplot(1, len(idx), k + 1)
        ax.imshow(frames[i])
        ax.set_title(f"step {i}", fontsize=8)
        ax.axis("off")
    written.append(_save(fig, path_base + "_strip.png"))
    return written


def save_all(exp, out: str, title: str = "", state_dims: Sequence[int] = (0, 1, 2),
             state_names: Optional[Sequence[str]] = None,
             distance_label: str = "distance to target", threshold: Optional[float] = None,
             marks: Optional[Sequence[int]] = None) -> List[str]:
    """Every figure of a finished :class:`pilco.experiment.Experiment` into ``out``.

    Writes ``distance.png``, ``cost_prediction.png`` (last learned episode),
    ``one_step.png`` (learned episodes), ``multi_step.png`` (last learned episode) and
    ``final_episode.gif`` / ``final_episode_strip.png`` when frames were rendered.
    A figure that fails is logged and skipped. Returns the written paths.
    """
    from .experiment.scoring import episode_costs

    names = list(state_names) if state_names is not None else [f"x[{d}]" for d in state_dims]
    written: List[str] = []
    eps = exp.episodes
    learned = [i for i, e in enumerate(eps) if not e.random]
    preds = exp.predictions

    def attempt(fn, *a, **kw):
        try:
            out_ = fn(*a, **kw)
            written.extend(out_ if isinstance(out_, list) else [out_])
        except Exception as err:  # keep drawing the others
            logger.warning("figure %s failed: %s", getattr(fn, "__name__", fn), err)

    attempt(plot_distances, [e.distances for e in eps], os.path.join(out, "distance.png"),
            random=[e.random for e in eps], threshold=threshold, ylabel=distance_label,
            title=title, marks=marks)
    with_pred = [i for i in learned if "pred_reward" in preds[i]]
    if with_pred:
        i = with_pred[-1]
        attempt(plot_cost_prediction, 1.0 - preds[i]["pred_reward"],
                preds[i]["pred_reward_var"],
                episode_costs(eps[i], exp.config),
                os.path.join(out, "cost_prediction.png"),
                title=f"{title} — episode {i + 1}: predicted vs real cost".strip(" —"))
        attempt(plot_multi_step, preds[i]["pred_mean"], preds[i]["pred_var"], eps[i].states,
                state_dims, names, os.path.join(out, "multi_step.png"),
                title=f"{title} — episode {i + 1}: multi-step prediction".strip(" —"))
    with_one = [i for i in learned if "onestep_mean" in preds[i]]
    if with_one:
        attempt(plot_one_step, [
            {"number": i + 1, "states": eps[i].states, "onestep_mean": preds[i]["onestep_mean"],
             "onestep_var": preds[i]["onestep_var"]} for i in with_one],
            state_dims, names, os.path.join(out, "one_step.png"),
            title=f"{title} — one-step predictions".strip(" —"))
    frames = exp.last_frames()
    if frames:
        attempt(save_frames, frames, os.path.join(out, "final_episode"))
    return written


def __getattr__(name: str):
    """``replay_fetch_frames``, the Fetch arm's renderer, lives in
    :mod:`pilco.envs.fetch_render`; it is imported from there on first use, so that
    importing this module does not import the environments."""
    if name == "replay_fetch_frames":
        from .envs.fetch_render import replay_fetch_frames

        return replay_fetch_frames
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list:
    return sorted(set(globals()) | {"replay_fetch_frames"})
