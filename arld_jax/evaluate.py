"""Deterministic evaluation rollouts, inside the jitted program."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from arld_jax.envs import Env
from arld_jax.types import PRNGKey


def rollout(
    env: Env,
    policy_fn: Callable[[jax.Array], jax.Array],
    key: PRNGKey,
    num_episodes: int,
    episode_length: int,
) -> tuple[jax.Array, jax.Array]:
    """Per episode [num_episodes]: the undiscounted return of `policy_fn` (obs [n, obs_dim] ->
    action [n, A]) over `episode_length` steps from a fresh random initial state, and the fraction
    of its visited states that are upside down (`env.upside_down`). Episodes run in parallel."""

    def step(state, _):  # noqa: ANN001, ANN202
        flipped = env.upside_down(state.obs)
        state = env.step(state, policy_fn(state.obs))
        return state, (state.reward, flipped)

    _, (rewards, flipped) = jax.lax.scan(
        step, env.reset(key, num_episodes), None, length=episode_length
    )
    return jnp.sum(rewards, axis=0), jnp.mean(flipped, axis=0)


def evaluate_policy(
    env: Env,
    policy_fn: Callable[[jax.Array], jax.Array],
    key: PRNGKey,
    num_episodes: int,
    episode_length: int,
) -> tuple[jax.Array, jax.Array]:
    """The mean over episodes of `rollout`: mean return and upside-down fraction."""
    returns, flipped = rollout(env, policy_fn, key, num_episodes, episode_length)
    return jnp.mean(returns), jnp.mean(flipped)
