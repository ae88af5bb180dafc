"""``python -m remoteenv latency-study``: does a policy that sees its actions in
flight keep its return as the action delay grows, where a delay-unaware one
collapses?

For every delay (constant ``k`` ticks, and random models ``U(low,high)``:
each action's delay uniform on ``low .. high`` ticks), every variant
(``plain``: the observation only; ``history``: the observation followed by the
actions in flight, plus under random delays the action in force and its age
alpha) and every seed, it trains Stable-Baselines3 PPO in lock-step (so every
run repeats from its seed; the policy follows the observation: an MLP for
values, a CNN for an image, multi-input for a Dict, the actions in flight a
separate input beside images) and evaluates the deterministic policy at the
delay it was trained under, beside fixed reference controllers. Then it runs
trained policies in real time with a think time, records each episode,
replays every recording in its exact twin (the same actions applied at the
same physics substeps, without the clock) and reports how many episodes the
twin reproduced bit for bit, with the first differing step of any other.

Outputs in ``--out``: ``delay_effect.json`` (every record, rewritten after
each finished run; ``--resume`` continues an interrupted study),
``delay_effect.png`` (per-seed points, mean ± std), ``delay_effect.md`` (the
table) and ``rt_replay.json``. The defaults are the study of docs/latency.md::

    python -m remoteenv latency-study --out docs/latency

Runs in the agent process (the command's own).
"""

from __future__ import annotations

import argparse
import os
import signal
import tempfile
from typing import Any

from remoteenv.cli.arguments import json_map, positive_int
from remoteenv.cli.latency_sweep import int_list
from remoteenv.cli.optional import require

DEFAULT_ENV = "remoteenv/CartPole-v0"
DEFAULT_RANDOM = "4:8,6:10,8:16,0:16"


def random_models(text: str) -> list[str]:
    """``"6:10,0:16"`` -> ``["U(6,10)", "U(0,16)"]`` (the study's model names)."""
    from remoteenv.latency.study.design import random_model, random_name

    names = []
    for part in text.split(","):
        bounds = part.strip().split(":")
        if len(bounds) != 2 or not all(b.strip().isdigit() for b in bounds):
            raise SystemExit(f"--random-delays: {part.strip()!r:.40} is not low:high in whole ticks (e.g. 6:10)")
        name = random_name(int(bounds[0]), int(bounds[1]))
        try:
            random_model(name)
        except ValueError as exc:
            raise SystemExit(f"--random-delays: {exc}") from None
        names.append(name)
    return names


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "latency-study",
        help="train PPO with and without the actions in flight across action delays; plot the effect",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    p.add_argument("--env", default=DEFAULT_ENV, help=f"a registered Gymnasium id (default {DEFAULT_ENV})")
    p.add_argument(
        "--env-kwargs",
        default=None,
        help="JSON map for the env (default '{\"continuous\": true}' for the default env, else {})",
    )
    p.add_argument("--delays", default="0,8,12", help="constant action delays in ticks; '' for none (default 0,8,12)")
    p.add_argument(
        "--random-delays",
        default=DEFAULT_RANDOM,
        help=f"random action delays as low:high in ticks (Uniform(low, high)); '' for none (default {DEFAULT_RANDOM})",
    )
    p.add_argument("--seeds", default="0,1,2", help="training seeds (default 0,1,2)")
    p.add_argument(
        "--steps", type=positive_int, default=400_000, help="environment steps per training run (default 400000)"
    )
    p.add_argument("--eval-episodes", type=positive_int, default=10, help="evaluation episodes per policy (default 10)")
    p.add_argument(
        "--workers",
        type=positive_int,
        default=min(2, os.cpu_count() or 1),
        help="training runs in parallel, one per core (default min(2, CPUs))",
    )
    p.add_argument(
        "--ppo",
        default="{}",
        help="JSON map of PPO settings to override (see remoteenv.latency.study.design.PPO_SETTINGS), e.g. '{\"gamma\": 0.98}'",
    )
    p.add_argument("--out", default="latency-study", help="output directory (default ./latency-study)")
    p.add_argument("--resume", action="store_true", help="keep the finished runs of an interrupted study in --out")
    p.add_argument(
        "--policies", default=None, help="keep the trained policies in this directory (default: a temporary one)"
    )
    p.add_argument("--no-plot", action="store_true", help="skip the figure (no matplotlib needed)")
    p.add_argument(
        "--rt-episodes",
        type=positive_int,
        default=5,
        help="real-time episodes per policy in the twin check (default 5: 30 for 2 variants x 3 seeds)",
    )
    p.add_argument("--no-rt-replay", action="store_true", help="skip the real-time / exact twin replay check")
    p.set_defaults(run=run)


def _config(args: argparse.Namespace) -> Any:
    from remoteenv.latency.study.design import StudyConfig

    if args.env_kwargs is None:
        kwargs: dict[str, Any] = {"continuous": True} if args.env == DEFAULT_ENV else {}
    else:
        kwargs = json_map(args.env_kwargs, "--env-kwargs")
    from remoteenv.delays import MAX_DELAY_TICKS

    delays = int_list(args.delays, "--delays", MAX_DELAY_TICKS) if args.delays.strip() else []
    random_delays = random_models(args.random_delays) if args.random_delays.strip() else []
    try:
        return StudyConfig(
            env_id=args.env,
            env_kwargs=kwargs,
            delays=tuple(delays),
            random_delays=tuple(random_delays),
            seeds=tuple(int_list(args.seeds, "--seeds")),
            steps=args.steps,
            eval_episodes=args.eval_episodes,
            ppo=json_map(args.ppo, "--ppo"),
        )
    except ValueError as exc:
        raise SystemExit(str(exc)) from None


def _check_spaces(config: Any) -> None:
    """Refuse spaces the study cannot train on, before it starts its sims (reading
    the spaces makes one env, whose sim is closed at once)."""
    from remoteenv.latency.study.trainable_spaces import check_spaces, probe_spaces

    observation_space, action_space = probe_spaces(config.env_id, config.env_kwargs)
    try:
        check_spaces(config.env_id, observation_space, action_space)
    except ValueError as exc:
        raise SystemExit(str(exc)) from None


def _check_writable(folder: str) -> None:
    """Fail now, not after an hour of training, if ``folder`` cannot take the outputs."""
    try:
        os.makedirs(folder, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".write-check-"):
            pass
    except OSError as exc:
        raise SystemExit(f"--out {folder!r} is not writable: {exc.strerror or exc}") from None


def _check_resumable(json_path: str, config: Any) -> None:
    """Refuse (one line, naming the file) a ``--resume`` file that is not an
    earlier run of this study (see :func:`remoteenv.latency.study.results.load_records`)."""
    from remoteenv.latency.study.results import load_records

    try:
        load_records(json_path, config)
    except (OSError, ValueError) as exc:
        raise SystemExit(f"latency-study --resume: {exc}") from None


def run(args: argparse.Namespace) -> int:
    purpose = "python -m remoteenv latency-study"
    for module in ("torch", "stable_baselines3", "tqdm") + (() if args.no_plot else ("matplotlib",)):
        require(module, purpose)
    config = _config(args)
    _check_spaces(config)
    _check_writable(args.out)
    if args.policies is not None:
        _check_writable(args.policies)
    json_path = os.path.join(args.out, "delay_effect.json")
    if args.resume:
        _check_resumable(json_path, config)  # now, not after the reference runs
    # SIGTERM ends the study as Ctrl-C does (the scratch dir is removed on the
    # way out); the dir reaper removes it even after a SIGKILL.
    previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        return _study(args, config, json_path)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _terminated(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def _study(args: argparse.Namespace, config: Any, json_path: str) -> int:
    from remoteenv.agent.launch.dir_reaper import forget_dir, watch_dir
    from remoteenv.latency.study.references import reference_returns
    from remoteenv.latency.study.results import markdown_table, plot, write_json
    from remoteenv.latency.study.runner import run_study
    from remoteenv.latency.study.twin_check import run_twin_check
    from remoteenv.wire.files.owned_dirs import remove_dir

    scratch = tempfile.mkdtemp(prefix="remoteenv-study-policies-")
    scratch_id = watch_dir(scratch)
    try:
        policy_dir = args.policies or scratch
        references = reference_returns(config)
        data = run_study(
            config, json_path, workers=args.workers, resume=args.resume, policy_dir=policy_dir, references=references
        )
        table = markdown_table(data["records"], references)
        with open(os.path.join(args.out, "delay_effect.md"), "w") as f:
            f.write(table + "\n")
        if not args.no_plot:
            seeds = f"{len(config.seeds)} seed{'s' if len(config.seeds) > 1 else ''}"
            title = f"{config.env_id}: PPO, {config.steps} steps per run, {seeds}"
            plot(data["records"], os.path.join(args.out, "delay_effect.png"), title, references)
        print(table)
        print(f"wrote {json_path} (training wall time {data['wall_s']:.0f} s on {data['host']['cpus']} CPUs)")
        if not args.no_rt_replay:
            check = run_twin_check(config, policy_dir, args.rt_episodes, progress=print)
            write_json(os.path.join(args.out, "rt_replay.json"), check)
            print(
                f"wrote {os.path.join(args.out, 'rt_replay.json')}: real time vs its exact twin, "
                f"{check['identical']} of {check['total']} episodes identical ({check['steps']} steps)"
            )
    finally:
        if scratch_id is not None:
            remove_dir(scratch, scratch_id)
        forget_dir(scratch)
    return 0
