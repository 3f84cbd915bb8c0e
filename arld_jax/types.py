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
