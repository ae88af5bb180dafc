"""Domain randomization: a different pole mass in every world of one vector env.

Each world of a :class:`remoteenv.RemoteVectorEnv` is its own MuJoCo model in
a sim process. ``set_attr`` reaches the scene env of each world (here
CartPole's ``pole_mass`` property, which scales the pole's mass and inertia),
so every world can have its own physics; ``get_attr`` reads them back, and
``call`` calls a scene method in each world. Run it::

    python examples/domain_randomization.py --num-envs 4 --episodes 2

It draws new masses before every episode and prints how long the LQR
controller keeps each pole up.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import remoteenv  # noqa: F401  (registers the remoteenv/ ids)
from remoteenv import controllers


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--num-envs", type=int, default=4)
    p.add_argument("--episodes", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    envs = gym.make_vec(
        "remoteenv/CartPole-v0",
        num_envs=args.num_envs,
        vectorization_mode="vector_entry_point",
        continuous=True,
        autoreset_mode=gym.vector.AutoresetMode.DISABLED,
    )
    try:
        for episode in range(args.episodes):
            masses = rng.uniform(0.05, 0.5, size=args.num_envs)
            envs.set_attr("pole_mass", [float(m) for m in masses])  # one value per world
            obs, _ = envs.reset(seed=args.seed + 100 * episode)
            steps = np.zeros(args.num_envs, dtype=np.int64)
            done = np.zeros(args.num_envs, dtype=bool)
            while not done.all():
                actions = np.stack([controllers.cartpole_continuous(o) for o in obs])
                obs, _, terminated, truncated, _ = envs.step(actions)
                steps += ~done
                done |= terminated | truncated
            got = envs.get_attr("pole_mass")
            print(f"episode {episode}: " + ", ".join(f"{m:.3f} kg -> {n} steps" for m, n in zip(got, steps)))
    finally:
        envs.close()


if __name__ == "__main__":
    main()
