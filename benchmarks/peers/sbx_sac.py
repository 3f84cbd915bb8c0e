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

The task's model can be another MJCF under Gymnasium's reward and health rule, to tell a learner's
part from the model's. Brax's Ant as arld_jax steps it (Brax's XML and the solver options
brax/envs/ant.py sets, its initial pose, its 27 observations, no contact cost):

    ../venv-sbx/bin/python benchmarks/peers/sbx_sac.py --env Ant-v5 --seed 0 \
        --xml-file "$(python -c 'import importlib.util as u; print(u.find_spec("brax").submodule_search_locations[0])')/envs/assets/ant.xml" \
        --env-kwarg include_cfrc_ext_in_observation=false --env-kwarg contact_cost_weight=0 \
        --model-opt iterations=1 --model-opt ls_iterations=4 --model-opt disable=eulerdamp \
        --init-qpos-from init_qpos --out experiments/sac_300k_peers/sbx-Ant-v5-brax-model-seed0.json
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.metadata
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any


def versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {}
    for pkg in ("sbx-rl", "stable-baselines3", "gymnasium", "mujoco", "jax", "flax", "optax"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def name_values(p: argparse.ArgumentParser, flag: str, items: list[str]) -> dict[str, str]:
    """`NAME=VALUE` items of a repeated `flag` as a dict, or a parser error naming the bad one."""
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            p.error(f"{flag} takes NAME=VALUE, got {item!r}")
        if name in out:
            p.error(f"{flag} {name} given twice ({out[name]!r} and {value!r}): give it once")
        out[name] = value
    return out


def set_model(
    p: argparse.ArgumentParser, env: Any, opts: dict[str, str], init_from: str | None
) -> None:
    """Set MuJoCo options `opts` on `env`'s model (`disable` takes `mjtDisableBit` names, lower
    case without `mjDSBL_`, comma-separated) and, with `init_from`, reset around the model's
    custom numeric of that name instead of its qpos0 (Brax reads its XMLs' `init_qpos` so)."""
    import mujoco
    import numpy as np

    u = env.unwrapped
    for name, value in opts.items():
        if name == "disable":
            for flag in value.split(","):
                bit = getattr(mujoco.mjtDisableBit, "mjDSBL_" + flag.upper(), None)
                if bit is None:
                    bits = dir(mujoco.mjtDisableBit)
                    allowed = [b[len("mjDSBL_") :].lower() for b in bits if b.startswith("mjDSBL_")]
                    p.error(f"--model-opt disable={value}: {flag!r} is none of {allowed}")
                u.model.opt.disableflags |= int(bit)
        elif isinstance(getattr(u.model.opt, name, None), int | float):
            kind = type(getattr(u.model.opt, name))
            try:
                setattr(u.model.opt, name, kind(float(value)))
            except ValueError:
                p.error(f"--model-opt {name}={value}: {name!r} takes a number")
        else:
            p.error(f"--model-opt {name}={value}: {name!r} is not a number of MuJoCo's opt")
    if init_from is not None:
        try:
            init = np.array(u.model.numeric(init_from).data, dtype=np.float64)
        except KeyError:
            p.error(f"--init-qpos-from {init_from}: the model has no custom numeric of that name")
        if init.shape != u.init_qpos.shape:
            p.error(
                f"--init-qpos-from {init_from}: {init.size} numbers, the model's nq is {u.model.nq}"
            )
        u.init_qpos = init


def add_model_args(p: argparse.ArgumentParser) -> None:
    """The flags that say which task and model Gymnasium's env runs (`env_maker` reads them)."""
    p.add_argument("--env", required=True, help="a Gymnasium task id, e.g. Hopper-v5")
    p.add_argument("--xml-file", help="the task's MJCF in place of Gymnasium's (its `xml_file`)")
    p.add_argument(
        "--env-kwarg",
        action="append",
        default=[],
        metavar="NAME=JSON",
        help="a keyword of gym.make, its value as JSON (e.g. contact_cost_weight=0); repeatable",
    )
    p.add_argument(
        "--model-opt",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set the model's opt.NAME (e.g. iterations=1), or disable=FLAG; repeatable",
    )
    p.add_argument(
        "--init-qpos-from",
        metavar="NUMERIC",
        help="reset around the model's custom numeric of this name (Brax's XMLs: init_qpos)",
    )


def env_maker(
    p: argparse.ArgumentParser, args: argparse.Namespace
) -> tuple[Callable[[], Any], dict[str, Any]]:
    """A function that makes the env `add_model_args`' flags name, and the record of its model
    for the JSON; a bad flag is a parser error before anything is built."""
    env_kwargs: dict[str, Any] = {}
    for name, value in name_values(p, "--env-kwarg", args.env_kwarg).items():
        try:
            env_kwargs[name] = json.loads(value)
        except json.JSONDecodeError:
            p.error(f"--env-kwarg {name}={value}: the value is not JSON (a string needs quotes)")
    model_opt = name_values(p, "--model-opt", args.model_opt)
    if args.xml_file is not None:
        if not Path(args.xml_file).is_file():
            p.error(f"--xml-file {args.xml_file}: no such file")
        env_kwargs["xml_file"] = str(Path(args.xml_file).resolve())

    import gymnasium as gym

    def make() -> gym.Env:
        try:
            env = gym.make(args.env, **env_kwargs)
        except TypeError as e:  # a keyword the task does not take
            p.error(f"--env-kwarg: {args.env} refused it: {e}")
        set_model(p, env, model_opt, args.init_qpos_from)
        return env

    obs_dim = int(make().observation_space.shape[0])  # every flag checked before training

    model_record = {
        "xml_file": Path(args.xml_file).name if args.xml_file else None,
        "xml_sha256": (
            hashlib.sha256(Path(args.xml_file).read_bytes()).hexdigest() if args.xml_file else None
        ),
        "env_kwargs": {k: v for k, v in env_kwargs.items() if k != "xml_file"},
        "model_opt": model_opt,
        "init_qpos_from": args.init_qpos_from,
        "obs_dim": obs_dim,
    }
    return make, model_record


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=300_000, help="env steps (default 300000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--eval-every", type=int, default=10_000)
    p.add_argument("--eval-episodes", type=int, default=10)
    p.add_argument("--out", required=True, help="the JSON file to write")
    add_model_args(p)
    args = p.parse_args(argv)
    for name in ("steps", "eval_every", "eval_episodes"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")

    make, model_record = env_maker(p, args)

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

    env, eval_env = make(), Monitor(make())
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
            "model": model_record,
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
