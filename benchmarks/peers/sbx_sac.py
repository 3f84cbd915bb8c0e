"""sbx's SAC (Stable Baselines Jax) on a Gymnasium v5 MuJoCo task: the peer a user picks for one env.

Run with the python of a separate virtual environment (`sbx-rl`, `gymnasium[mujoco]`; it imports
nothing from arld_jax):

    python -m venv ../venv-sbx && ../venv-sbx/bin/pip install torch==2.13.0 sbx-rl "gymnasium[mujoco]"
    ../venv-sbx/bin/python benchmarks/peers/sbx_sac.py --env Hopper-v5 --seed 0 \
        --out experiments/sac_300k_peers/sbx-Hopper-v5-seed0.json

SAC at sbx's defaults (what a user of sbx gets: 2x256 networks, batch 256, learning rate 3e-4,
entropy coefficient tuned automatically), one gradient step per env step, 1 env. Every
`--eval-every` env steps, `--eval-episodes` deterministic episodes on a separate env (SB3's
`evaluate_policy`); the JSON holds those returns with the versions and the model's
hyperparameters. It is rewritten after every evaluation (`"complete": false` until the last
step), so a run cut short keeps the evaluations it made; sbx cannot resume it.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import time
from collections.abc import Callable
from pathlib import Path


def versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {}
    for pkg in ("sbx-rl", "stable-baselines3", "gymnasium", "mujoco", "jax", "flax", "optax"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--env", required=True, help="a Gymnasium task id, e.g. Hopper-v5")
    p.add_argument("--steps", type=int, default=300_000, help="env steps (default 300000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--eval-every", type=int, default=10_000)
    p.add_argument("--eval-episodes", type=int, default=10)
    p.add_argument("--out", required=True, help="the JSON file to write")
    args = p.parse_args(argv)
    for name in ("steps", "eval_every", "eval_episodes"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")

    import gymnasium as gym
    from sbx import SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    class Evaluate(BaseCallback):
        """Deterministic episodes on `eval_env` every `every` env steps (1 env: one step per call)."""

        def __init__(
            self, eval_env: gym.Env, every: int, episodes: int, report: Callable[[bool], dict]
        ) -> None:
            super().__init__()
            self.eval_env, self.every, self.episodes = eval_env, every, episodes
            self.report = report  # writes the JSON; called after every evaluation
            self.steps: list[int] = []
            self.returns: list[list[float]] = []
            self.lengths: list[list[int]] = []

        def _on_step(self) -> bool:
            if self.num_timesteps % self.every == 0:
                returns, lengths = evaluate_policy(
                    self.model,
                    self.eval_env,
                    n_eval_episodes=self.episodes,
                    deterministic=True,
                    return_episode_rewards=True,
                )
                self.steps.append(int(self.num_timesteps))
                self.returns.append([float(r) for r in returns])
                self.lengths.append([int(n) for n in lengths])
                self.report(False)
            return True

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    env, eval_env = gym.make(args.env), Monitor(gym.make(args.env))
    eval_env.reset(seed=10_000 + args.seed)  # fresh episodes, not the training env's
    model = SAC("MlpPolicy", env, seed=args.seed, verbose=0)
    hyper = {
        k: (v if isinstance(v, int | float | str | bool) or v is None else str(v))
        for k, v in vars(model).items()
        if k
        in (
            "learning_rate",
            "buffer_size",
            "learning_starts",
            "batch_size",
            "tau",
            "gamma",
            "train_freq",
            "gradient_steps",
            "ent_coef",
            "target_entropy",
            "policy_kwargs",
        )
    }
    installed = versions()
    start = time.time()

    def write_report(complete: bool) -> dict:
        report = {
            "peer": "sbx SAC",
            "env": args.env,
            "seed": args.seed,
            "steps": args.steps,
            "complete": complete,
            "eval_every": args.eval_every,
            "eval_episodes": args.eval_episodes,
            "eval_env_steps": evaluate.steps,
            "eval_returns": evaluate.returns,
            "eval_lengths": evaluate.lengths,
            "wall_s": round(time.time() - start, 1),
            "hyperparameters": hyper,
            "versions": installed,
        }
        out.write_text(json.dumps(report, indent=1) + "\n")
        return report

    evaluate = Evaluate(eval_env, args.eval_every, args.eval_episodes, write_report)
    model.learn(total_timesteps=args.steps, callback=evaluate)
    report = write_report(True)
    wall = report["wall_s"]
    final = report["eval_returns"][-1] if report["eval_returns"] else []
    mean = sum(final) / len(final) if final else float("nan")
    print(f"{args.env} seed {args.seed}: final deterministic return {mean:.1f} ({wall:.0f} s)")


if __name__ == "__main__":
    main()
