"""Trains PPO from stable-baselines3 on an ocm-rl task and scores it against the expert.

Not part of the tests (it needs stable-baselines3 and PyTorch and runs for minutes):

    .venv/bin/pip install stable-baselines3
    .venv/bin/python host/rl/py/examples/train_sb3.py --model S/surrogate.json --task circle \
        --steps 200000 --seed 1 --out out/sb3_circle

S/surrogate.json is the model of `ocm surrogate map` (see host/surrogate/README.md). The script
prints the mean TCP error (mm) of the trained deterministic policy and of the inverse-model
expert on five evaluation episodes whose seeds (2,000,000..) are disjoint from training, and saves
the policy to OUT/ppo.zip.
"""

from __future__ import annotations

import argparse
import os

import numpy as np

import ocm_rl

EVAL_SEEDS = range(2_000_000, 2_000_005)


def mean_error_mm(env: ocm_rl.OcmEnv, act) -> float:
    """Mean TCP distance to the step's target over the evaluation episodes, mm."""
    errors = []
    for seed in EVAL_SEEDS:
        obs, _ = env.reset(seed=seed)
        while True:
            obs, _, term, trunc, info = env.step(act(obs))
            errors.append(info["position_error_m"])
            if term or trunc:
                break
    return 1e3 * float(np.mean(errors))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--model", required=True, help="surrogate.json of `ocm surrogate map`")
    p.add_argument("--task", default="circle", choices=ocm_rl.TASKS)
    p.add_argument("--steps", type=int, default=200_000, help="environment steps of training")
    p.add_argument("--envs", type=int, default=8, help="environments stepped per rollout")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default="out/sb3")
    args = p.parse_args()

    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    # SB3 brings its own vectorisation (a DummyVecEnv of single environments); the seeds of its
    # environments are seed, seed + 1, ...
    venv = make_vec_env(
        ocm_rl.OcmEnv,
        n_envs=args.envs,
        seed=args.seed,
        env_kwargs={"task": args.task, "model": args.model},
    )
    agent = PPO(
        "MlpPolicy",
        venv,
        n_steps=100,  # one episode of 100 targets per environment and rollout
        batch_size=200,
        gamma=0.95,
        gae_lambda=0.95,
        learning_rate=3e-4,
        n_epochs=8,
        # Like `ocm rl train --algo ppo`: two hidden layers of 128 and a small exploration noise;
        # SB3's default standard deviation of 1 covers the whole action box and loses the TCP.
        policy_kwargs={"net_arch": [128, 128], "log_std_init": -1.6},
        seed=args.seed,
        verbose=1,
    )
    agent.learn(total_timesteps=args.steps)
    os.makedirs(args.out, exist_ok=True)
    agent.save(os.path.join(args.out, "ppo.zip"))

    env = ocm_rl.OcmEnv(args.task, model=args.model)
    ppo_mm = mean_error_mm(env, lambda obs: agent.predict(obs, deterministic=True)[0])
    expert_mm = mean_error_mm(env, lambda obs: env.expert_action())
    print(f"{args.task}: PPO {ppo_mm:.3f} mm, expert {expert_mm:.3f} mm "
          f"(mean TCP error over {len(EVAL_SEEDS)} episodes of 100 points)")


if __name__ == "__main__":
    main()
