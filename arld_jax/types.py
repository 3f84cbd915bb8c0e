"""Shared type aliases and the replay item."""

from __future__ import annotations

from typing import Any

import flax.struct
import jax

PRNGKey = jax.Array
Params = Any  # a pytree of parameter arrays
Metrics = dict[str, jax.Array]


@flax.struct.dataclass
class Transition:
    """One stored environment step. `action` is the action that was executed (the expert's when the
    step was demonstrated). `next_obs` is the true next observation, also at a time limit, so the
    critic bootstraps through truncation (HalfCheetah never terminates)."""

    obs: jax.Array  # [obs_dim]
    action: jax.Array  # [action_dim], in [-1, 1]
    reward: jax.Array  # []
    next_obs: jax.Array  # [obs_dim]
    terminated: jax.Array  # [] float32, 1.0 stops bootstrapping
    is_demo: jax.Array  # [] float32, 1.0 if the expert acted (adds eps_demo to its priority)


def example_transition(obs_dim: int, action_dim: int) -> Transition:
    """One replay item of the given sizes (zeros): the replay's layout (`replay.init`)."""
    import jax.numpy as jnp

    return Transition(
        obs=jnp.zeros(obs_dim),
        action=jnp.zeros(action_dim),
        reward=jnp.zeros(()),
        next_obs=jnp.zeros(obs_dim),
        terminated=jnp.zeros(()),
        is_demo=jnp.zeros(()),
    )
