"""Adaptation to damage: learn to reach on the healthy Fetch arm, then break a joint
mid-run and keep learning with the same agent (the paper's motivation, §5.2).

1. one random episode and up to ``--healthy-episodes`` learned episodes on the healthy
   arm, stopping as soon as an episode reaches the target;
2. ``env.damage(--damaged-joints, --damage-mode)`` (the policy is not told; by default
   the elbow is stuck at its angle, ``--damage-mode zero`` straightens it as the paper's
   damaged reacher does); the start state of the damaged arm becomes the agent's
   ``m_init``;
3. up to ``--damaged-episodes`` learned episodes with the same agent, policy and data
   (``--drop-old-data``: the model then learns from the damaged episodes only), stopping
   once it reaches again (unless ``--no-stop-when-recovered``).

Every reacher setting of ``examples/reacher.py`` is a flag here too. The summary adds
``"damage_at_episode"`` (first episode on the damaged arm) and ``"episodes_to_recover"``
(damaged episodes until one reaches, counting that one; null if none did).
Figure ``adaptation_distance.png``: distance per step, healthy and damaged episodes.

Usage::

    python examples/adaptation.py --seed 0
"""
from __future__ import annotations

import os
import sys
from typing import Optional, Sequence

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import reacher  # noqa: E402 - the shared reacher settings


def build_parser():
    parser = reacher.build_parser(damaged=False)
    parser.description = "PILCO on the Fetch reacher, adapting to a joint damaged mid-run"
    # the elbow breaks where it is (stuck at its start angle), so the arm starts where the
    # healthy one did and the healthy cost width still applies; --damage-mode zero
    # straightens it (1.17 m from the target: add --cost-width 0.4 then)
    parser.set_defaults(output="runs/adaptation-seed{seed}", episodes=None,
                        damage_mode="stuck")
    g = parser.add_argument_group("adaptation")
    g.add_argument("--healthy-episodes", type=int, default=4,
                   help="at most this many learned episodes before the damage")
    g.add_argument("--damaged-episodes", type=int, default=4,
                   help="at most this many learned episodes after the damage")
    g.add_argument("--drop-old-data", action="store_true",
                   help="after the damage, learn the model from damaged episodes only")
    g.add_argument("--no-stop-when-recovered", action="store_true",
                   help="run all --damaged-episodes even after reaching again")
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    from pilco import plotting, runner

    parser = build_parser()
    args = runner.parse_args_with_resume(parser, argv)
    runner.configure_logging(args.log_level)
    args.episodes = args.random_episodes + args.healthy_episodes + args.damaged_episodes
    config = reacher.make_config(args, "adaptation", damaged=False)

    exp, env = reacher.make_experiment(args, config)
    extra = exp.extra.setdefault("summary", {"damage_at_episode": None,
                                             "episodes_to_recover": None})

    def damage_now():
        env.unwrapped.damage(tuple(args.damaged_joints), args.damage_mode)
        obs, _ = env.reset(seed=exp._episode_seed(len(exp.episodes) + 1))  # noqa: SLF001
        exp.agent.m_init = obs[None, :]  # the damaged arm may start elsewhere

    with exp.session():
        while len(exp.episodes) < args.random_episodes:
            exp.run_random_episode()
        if extra["damage_at_episode"] is None:
            healthy = sum(not r["random"] for r in exp.records)
            solved = any(not r["random"] and exp.episode_solved(e)
                         for r, e in zip(exp.records, exp.episodes))
            while healthy < args.healthy_episodes and not solved:
                exp.run_learned_episode()
                healthy += 1
                solved = exp.episode_solved(exp.episodes[-1])
            damage_now()
            extra["damage_at_episode"] = len(exp.episodes) + 1
            if args.drop_old_data:
                exp.extra["train_from_episode"] = extra["damage_at_episode"]
            exp.save_progress()
        else:
            damage_now()  # resuming after the damage: break the fresh env again
        first = extra["damage_at_episode"]
        while len(exp.episodes) - first + 1 < args.damaged_episodes:
            if extra["episodes_to_recover"] is not None and not args.no_stop_when_recovered:
                break
            exp.run_learned_episode()
            if extra["episodes_to_recover"] is None and exp.episode_solved(exp.episodes[-1]):
                extra["episodes_to_recover"] = len(exp.episodes) - first + 1
            exp.save_progress()
    summary = exp.summary()
    print(runner.format_episode_table(summary))
    print(f"\ndamage at episode {summary['damage_at_episode']}; episodes to recover: "
          f"{summary['episodes_to_recover']}")
    print(runner.format_timing_table(summary["seconds"], title="Timing (adaptation)"))
    if exp.interrupted:
        print(f"\nInterrupted: agent and data saved in {exp.directory}; continue with "
              f"--resume {exp.directory}")
        exp.close()
        return 130
    if not args.no_figures:
        first = summary["damage_at_episode"]
        kinds = ["random" if e.random else "healthy" if i + 1 < first else "damaged"
                 for i, e in enumerate(exp.episodes)]
        labels = [f"episode {i + 1} ({k})" for i, k in enumerate(kinds)]
        paths = [plotting.plot_distances(
            [e.distances for e in exp.episodes],
            os.path.join(exp.directory, "adaptation_distance.png"),
            random=[e.random for e in exp.episodes], threshold=args.threshold,
            ylabel="distance to target [m]", labels=labels, marks=[first],
            title=f"damage ({', '.join(args.damaged_joints)}, {args.damage_mode}) "
                  f"before episode {first}")]
        paths += reacher.reacher_figures(exp, exp.directory, title="adaptation")
        print(f"\nFigures: {', '.join(os.path.basename(p) for p in paths)}")
    exp.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
