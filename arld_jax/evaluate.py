"""Deterministic evaluation rollouts, inside the jitted program."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from arld_jax.envs import Env
from arld_jax.types import PRNGKey


def evaluate_policy(
    env: Env,
    policy_fn: Callable[[jax.Array], jax.Array],
    key: PRNGKey,
    num_episodes: int,
    episode_length: int,
) -> tuple[jax.Array, jax.Array]:
    """Mean undiscounted return of `policy_fn` (obs [n, obs_dim] -> action [n, A]) over `num_episodes`
    parallel episodes of `episode_length` steps, each from a fresh random initial state, and the
    fraction of the visited states that are upside down (`env.upside_down`)."""

    def step(state, _):  # noqa: ANN001, ANN202
        flipped = jnp.mean(env.upside_down(state.obs))
        state = env.step(state, policy_fn(state.obs))
        return state, (state.reward, flipped)

    _, (rewards, flipped) = jax.lax.scan(
        step, env.reset(key, num_episodes), None, length=episode_length
    )
    return jnp.mean(jnp.sum(rewards, axis=0)), jnp.mean(flipped)
