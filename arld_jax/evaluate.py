"""Deterministic evaluation rollouts, inside the jitted program."""

from __future__ import annotations

from collections.abc import Callable

import flax.struct
import jax
import jax.numpy as jnp

from arld_jax.envs import Env
from arld_jax.tasks.base import select_envs
from arld_jax.types import PRNGKey


@flax.struct.dataclass
class Evaluation:
    """Per episode [num_episodes] (`rollout`), or their means (`evaluate_policy`)."""

    episode_return: jax.Array  # undiscounted return up to the episode's end
    upside_down: jax.Array  # fraction of the episode's visited states that are upside down
    fell: jax.Array  # 1.0 where the episode ended by a termination (the task's health rule)
    length: jax.Array  # steps until the episode ended (the time limit if it never fell)


def rollout(
    env: Env,
    policy_fn: Callable[[jax.Array], jax.Array],
    key: PRNGKey,
    num_episodes: int,
    episode_length: int,
) -> Evaluation:
    """`num_episodes` episodes of `policy_fn` (obs [n, obs_dim] -> action [n, A]) in parallel, each
    from a fresh random initial state, ending at a termination or after `episode_length` steps.

    An episode that ended stays frozen in its last state (a select per step, only for tasks that can
    terminate) and earns nothing more: the terminal step's reward counts, nothing after it."""

    def step(carry, _):  # noqa: ANN001, ANN202
        state, alive = carry
        flipped = env.upside_down(state.obs)
        nxt = env.step(state, policy_fn(state.obs))
        reward = jnp.where(alive, nxt.reward, 0.0)
        if env.can_terminate:
            nxt = select_envs(alive, nxt, state)
            ended = alive & (nxt.terminated > 0)
        else:
            ended = jnp.zeros_like(alive)
        return (nxt, alive & ~ended), (reward, flipped, alive, ended)

    alive0 = jnp.ones(num_episodes, bool)
    _, (rewards, flipped, alive, ended) = jax.lax.scan(
        step, (env.reset(key, num_episodes), alive0), None, length=episode_length
    )
    steps = jnp.sum(alive, axis=0)  # [num_episodes]: steps taken, the terminal one included
    return Evaluation(
        episode_return=jnp.sum(rewards, axis=0),
        upside_down=jnp.sum(flipped & alive, axis=0) / steps,
        fell=jnp.any(ended, axis=0).astype(jnp.float32),
        length=steps.astype(jnp.float32),
    )


def evaluate_policy(
    env: Env,
    policy_fn: Callable[[jax.Array], jax.Array],
    key: PRNGKey,
    num_episodes: int,
    episode_length: int,
) -> Evaluation:
    """The means over episodes of `rollout`."""
    return jax.tree.map(jnp.mean, rollout(env, policy_fn, key, num_episodes, episode_length))
