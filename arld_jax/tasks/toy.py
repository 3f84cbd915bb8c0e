"""toy: a seconds-to-compile pure-JAX stand-in with HalfCheetah's interface, for tests and smoke
runs (no physics: the same on every backend), and its closed-form expert.

reward = 1 - e, e = mean_j (a_j - tanh(2 W s)_j)^2, s' = clip(0.9 s + 0.3 [a, -a], -2, 2). The
best policy earns 1 per step, always acting 0 about 0.4, uniform-random actions about 0. It never
ends early; `toy_fall` is the same task with a fall.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from arld_jax.tasks.base import Env, EnvState, TaskSpec, never_upside_down
from arld_jax.types import PRNGKey

# A fixed random linear map for the target action; numpy so it is a compile-time constant.
_TOY_OBS_DIM, _TOY_ACTION_DIM = 4, 2
_TOY_W = np.random.default_rng(0).normal(size=(_TOY_OBS_DIM, _TOY_ACTION_DIM)).astype(np.float32)


def toy_target_action(obs: jax.Array) -> jax.Array:
    """The toy env's best action in state `obs` (the 'expert' of the tests)."""
    return jnp.tanh(2.0 * obs @ _TOY_W)


def toy_env(fall_error: float | None = None) -> Env:
    """The toy task; with `fall_error` (the `toy_fall` task), a step with e > fall_error
    terminates the episode, its reward is paid and nothing after it."""

    def reset(key: PRNGKey, n: int) -> EnvState:
        s = jax.random.uniform(key, (n, _TOY_OBS_DIM), minval=-1.0, maxval=1.0)
        return EnvState(inner=s, obs=s, reward=jnp.zeros(n), terminated=jnp.zeros(n))

    def step(state: EnvState, action: jax.Array) -> EnvState:
        s = state.inner
        error = jnp.mean(jnp.square(action - toy_target_action(s)), axis=-1)
        s_next = jnp.clip(0.9 * s + 0.3 * jnp.concatenate([action, -action], axis=-1), -2.0, 2.0)
        fell = jnp.zeros_like(error) if fall_error is None else (error > fall_error)
        return EnvState(
            inner=s_next, obs=s_next, reward=1.0 - error, terminated=fell.astype(jnp.float32)
        )

    return Env(
        reset=reset,
        step=step,
        obs_dim=_TOY_OBS_DIM,
        action_dim=_TOY_ACTION_DIM,
        upside_down=never_upside_down,
        can_terminate=fall_error is not None,
    )


SPEC = TaskSpec(
    name="toy",
    summary="a pure-JAX stand-in for tests, never ends early (obs 4, action 2)",
    can_terminate=False,
    make_pure=toy_env,
    target_action=toy_target_action,
)
