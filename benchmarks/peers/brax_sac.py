"""Brax's own SAC trainer on MJX HalfCheetah, timed at every progress call (a `peers` child).

Run by `python -m benchmarks.bench --only peers` with the python of a separate virtual environment
(jax 0.9.2, brax 0.14.2: Brax's trainers fail on the project's jax 0.10). It imports nothing from
arld_jax. It prints one JSON line per event on stdout, each prefixed with `PEER_MARKER`:

    {"event": "info", ...versions and devices...}
    {"event": "progress", "step": env steps, "t": seconds since train() was called, "metrics": {...}}
    {"event": "done", "t": ..., "num_training_steps_per_epoch": ..., ...}

Brax calls `progress_fn` once after the initial evaluation (step 0) and once after every training
epoch + evaluation. From the second epoch on nothing compiles any more, so the rate between two
later progress calls is the steady-state rate of one epoch and one evaluation.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import sys
import time

PEER_MARKER = "PEER_EVENT "


def emit(event: str, **fields: object) -> None:
    print(PEER_MARKER + json.dumps({"event": event, **fields}, default=float), flush=True)


def versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {}
    for pkg in ("jax", "jaxlib", "brax", "mujoco", "mujoco-mjx", "flax", "optax", "numpy"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--num-envs", type=int, required=True)
    p.add_argument("--num-timesteps", type=int, required=True)
    p.add_argument("--num-evals", type=int, required=True)
    p.add_argument("--num-eval-envs", type=int, required=True)
    p.add_argument("--min-replay-size", type=int, required=True)
    p.add_argument("--max-replay-size", type=int, required=True)
    p.add_argument("--batch-size", type=int, default=256)
    p.add_argument("--episode-length", type=int, default=1000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--versions-only", action="store_true", help="print the info line and exit")
    args = p.parse_args(argv)

    import jax

    emit(
        "info",
        versions=versions(),
        python=sys.version.split()[0],
        devices=[str(d) for d in jax.devices()],
        xla_flags=os.environ.get("XLA_FLAGS", ""),
    )
    if args.versions_only:
        return

    from brax import envs
    from brax.training.agents.sac import train as sac

    env = envs.get_environment("halfcheetah", backend="mjx")
    keep = (
        "eval/episode_reward",
        "eval/epoch_eval_time",
        "eval/walltime",
        "eval/sps",
        "training/sps",
        "training/walltime",
    )
    start = time.perf_counter()

    def progress(step: int, metrics: dict) -> None:
        emit(
            "progress",
            step=int(step),
            t=time.perf_counter() - start,
            metrics={k: float(metrics[k]) for k in keep if k in metrics},
        )

    # One gradient update per env step: Brax does `grad_updates_per_step` updates per actor step,
    # and one actor step steps all `num_envs` envs.
    sac.train(
        environment=env,
        num_timesteps=args.num_timesteps,
        episode_length=args.episode_length,
        num_envs=args.num_envs,
        num_eval_envs=args.num_eval_envs,
        learning_rate=3e-4,
        discounting=0.99,
        seed=args.seed,
        batch_size=args.batch_size,
        num_evals=args.num_evals,
        normalize_observations=False,
        reward_scaling=1.0,
        tau=0.005,
        min_replay_size=args.min_replay_size,
        max_replay_size=args.max_replay_size,
        grad_updates_per_step=args.num_envs,
        deterministic_eval=True,
        progress_fn=progress,
    )
    prefill_actor_steps = -(-args.min_replay_size // args.num_envs)
    epochs = max(args.num_evals - 1, 1)
    emit(
        "done",
        t=time.perf_counter() - start,
        prefill_env_steps=prefill_actor_steps * args.num_envs,
        num_training_steps_per_epoch=-(
            -(args.num_timesteps - prefill_actor_steps * args.num_envs) // (epochs * args.num_envs)
        ),
        epochs=epochs,
    )


if __name__ == "__main__":
    main()
