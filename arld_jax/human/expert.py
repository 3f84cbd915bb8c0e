"""A person as the expert: an `Expert` whose `act` is an ordered `io_callback` into a DemoSession.

The loop calls `expert.act` only inside `lax.cond(any(context.is_demo), ...)` (arld_jax/train.py),
so the callback runs exactly at the iterations the query strategy demonstrates, and blocks there
until the person has acted: the scanned program simply waits. `ordered=True` keeps the calls in
loop order (one person, one sequence of steps) and cannot be vmapped (jax refuses "Cannot `vmap`
ordered IO callback"): a person demonstrates for one run, trained with `jax.jit(run_periods)`.

Behaviour cloning of a recorded set of demonstrations (`clone_expert`) gives back an ordinary saved
expert (`arld_jax.expert.save_expert`), usable as `--expert_path` in the vmapped sweeps.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import io_callback

from arld_jax.expert import Expert, ExpertContext
from arld_jax.human.dataset import person_pairs, read_dataset
from arld_jax.human.session import DemoSession
from arld_jax.types import Params, PRNGKey


def make_human_expert(session: DemoSession) -> Expert:
    """The person at `session`'s page as an `Expert` (not vmappable: one run only)."""
    action_dim = session.run.action_dim

    def act(params: Params, obs: jax.Array, key: PRNGKey, context: ExpertContext) -> jax.Array:
        del params, key
        shape = jax.ShapeDtypeStruct((obs.shape[0], action_dim), jnp.float32)
        new_query = jnp.broadcast_to(context.new_query, context.is_demo.shape)
        return io_callback(
            session.demonstrate,
            shape,
            obs,
            context.agent_action,
            context.uncertainty,
            context.is_demo,
            new_query,
            context.demo_remaining,
            context.demos_used,
            context.budget,
            context.env_step,
            ordered=True,
        )

    meta = {"name": "person", "kind": "human", "dataset": str(session.dataset.path)}
    return Expert(params={}, act=act, meta=meta, observe=make_observer(session))


def make_observer(
    session: DemoSession,
) -> Callable[[jax.Array, jax.Array, jax.Array, ExpertContext], jax.Array]:
    """observe(obs, next_obs, fell, context): hands every iteration's states, and the states where
    an env fell, to the session (the frames before a query, the falls, and pausing between
    queries). The loop's per-iteration hook (`Expert.observe`)."""

    def observe(
        obs: jax.Array, next_obs: jax.Array, fell: jax.Array, context: ExpertContext
    ) -> jax.Array:
        return io_callback(
            session.observe,
            jax.ShapeDtypeStruct((), jnp.int32),
            obs,
            next_obs,
            fell,
            context.env_step,
            ordered=True,
        )

    return observe


# ---------------------------------------------------------------- behaviour cloning


def fit_actor(
    obs: np.ndarray,
    action: np.ndarray,
    hidden_sizes: tuple[int, ...] = (64, 64),
    steps: int = 2_000,
    learning_rate: float = 3e-3,
    seed: int = 0,
) -> tuple[Any, Params, float]:
    """Fit an `Actor`'s deterministic action tanh(mu(s)) to the recorded actions (mean squared
    error, Adam, full batch). Returns (actor, params, final training MSE)."""
    import optax

    from arld_jax.networks import Actor, deterministic_action

    obs, action = jnp.asarray(obs, jnp.float32), jnp.asarray(action, jnp.float32)
    actor = Actor(action_dim=action.shape[1], hidden_sizes=tuple(hidden_sizes))
    k_init, k_noise = jax.random.split(jax.random.key(seed))
    params = actor.init(k_init, obs[:1], k_noise, jnp.float32(0.0))
    opt = optax.adam(learning_rate)

    def loss_fn(p: Params) -> jax.Array:
        pred = deterministic_action(actor.apply(p, obs, k_noise, jnp.float32(0.0)))
        return jnp.mean(jnp.square(pred - action))

    def step(carry, _):  # noqa: ANN001, ANN202
        p, s = carry
        loss, grads = jax.value_and_grad(loss_fn)(p)
        updates, s = opt.update(grads, s, p)
        return (optax.apply_updates(p, updates), s), loss

    (params, _), _ = jax.jit(lambda p: jax.lax.scan(step, (p, opt.init(p)), None, length=steps))(
        params
    )
    return actor, params, float(loss_fn(params))


def clone_expert(
    dataset_path: str | Path,
    out: str | Path,
    hidden_sizes: tuple[int, ...] = (64, 64),
    steps: int = 2_000,
    seed: int = 0,
) -> Expert:
    """Behaviour-clone the person's recorded demonstrations into a saved expert at `out`
    (`arld_jax.expert.save_expert`: pass `--expert_path out` to any sweep) and return it.

    Only the steps the person demonstrated are used (hand-backs are the agent's actions)."""
    from arld_jax.expert import expert_from_actor, save_expert

    header, records = read_dataset(dataset_path)
    obs, action = person_pairs(records)
    if len(obs) == 0:
        raise ValueError(f"{dataset_path} holds no demonstrated step to clone")
    actor, params, mse = fit_actor(obs, action, hidden_sizes, steps, seed=seed)
    meta = {
        "env_name": header["env_name"],
        "obs_dim": header["obs_dim"],
        "action_dim": header["action_dim"],
        "hidden_sizes": list(hidden_sizes),
        "log_std_min": actor.log_std_min,
        "log_std_max": actor.log_std_max,
        "kind": "behaviour_cloning",
        "source_dataset": str(Path(dataset_path).absolute()),
        "num_demonstrations": int(len(obs)),
        "train_mse": mse,
        "fit_steps": steps,
    }
    save_expert(out, params, meta)
    return expert_from_actor(actor, params, meta)
