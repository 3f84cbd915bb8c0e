"""Batched environments: MJX HalfCheetah through Brax, and a cheap pure-JAX stand-in for tests.

`make_env(cfg)` returns reset/step functions over a leading env axis. Time limits and resets are NOT
handled here: HalfCheetah never terminates, so every episode lasts exactly `cfg.episode_length` steps
and all envs of a run start and end together. The training loop therefore resets all envs at the
iteration that ends an episode, from fresh random initial states (Brax's AutoResetWrapper would
replay the first initial state forever), under a `lax.cond` whose predicate depends only on the
iteration index, so the reset costs nothing on the other 999 steps, also under `vmap` over seeds.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np

from arld_jax.config import Config
from arld_jax.types import PRNGKey


@flax.struct.dataclass
class EnvState:
    """A batch of environment states. `obs` after a step is the true next observation."""

    inner: Any  # backend state (Brax State, or the toy env's state vector)
    obs: jax.Array  # [num_envs, obs_dim]
    reward: jax.Array  # [num_envs]
    terminated: jax.Array  # [num_envs] float32 (always 0 for HalfCheetah)


class Env(NamedTuple):
    reset: Callable[[PRNGKey, int], EnvState]  # (key, n) -> n fresh random initial states
    step: Callable[[EnvState, jax.Array], EnvState]  # (state [n], action [n, A]) -> state [n]
    obs_dim: int
    action_dim: int


def make_env(cfg: Config) -> Env:
    """The batched env named by `cfg.env_name`."""
    if cfg.env_name == "halfcheetah":
        return _brax_env("halfcheetah", cfg.backend)
    return _toy_env()


def _brax_env(name: str, backend: str) -> Env:
    from brax import envs as brax_envs  # imported lazily: the toy env and unit tests do not need it

    env = brax_envs.get_environment(name, backend=backend)

    def wrap(s: Any) -> EnvState:
        return EnvState(inner=s, obs=s.obs, reward=s.reward, terminated=s.done)

    def reset(key: PRNGKey, n: int) -> EnvState:
        return wrap(jax.vmap(env.reset)(jax.random.split(key, n)))

    def step(state: EnvState, action: jax.Array) -> EnvState:
        return wrap(jax.vmap(env.step)(state.inner, action))

    return Env(reset=reset, step=step, obs_dim=env.observation_size, action_dim=env.action_size)


# A fixed random linear map for the toy env's target action; numpy so it is a compile-time constant.
_TOY_OBS_DIM, _TOY_ACTION_DIM = 4, 2
_TOY_W = np.random.default_rng(0).normal(size=(_TOY_OBS_DIM, _TOY_ACTION_DIM)).astype(np.float32)


def toy_target_action(obs: jax.Array) -> jax.Array:
    """The toy env's best action in state `obs` (the 'expert' of the tests)."""
    return jnp.tanh(2.0 * obs @ _TOY_W)


def _toy_env() -> Env:
    """A seconds-to-compile stand-in with HalfCheetah's interface (fixed-length, never terminates).

    reward = 1 - mean_j (a_j - tanh(2 W s)_j)^2, s' = clip(0.9 s + 0.3 [a, -a], -2, 2). The best
    policy earns 1 per step, always acting 0 about 0.4, uniform-random actions about 0.
    """

    def reset(key: PRNGKey, n: int) -> EnvState:
        s = jax.random.uniform(key, (n, _TOY_OBS_DIM), minval=-1.0, maxval=1.0)
        return EnvState(inner=s, obs=s, reward=jnp.zeros(n), terminated=jnp.zeros(n))

    def step(state: EnvState, action: jax.Array) -> EnvState:
        s = state.inner
        reward = 1.0 - jnp.mean(jnp.square(action - toy_target_action(s)), axis=-1)
        s_next = jnp.clip(0.9 * s + 0.3 * jnp.concatenate([action, -action], axis=-1), -2.0, 2.0)
        return EnvState(inner=s_next, obs=s_next, reward=reward, terminated=jnp.zeros_like(reward))

    return Env(reset=reset, step=step, obs_dim=_TOY_OBS_DIM, action_dim=_TOY_ACTION_DIM)
