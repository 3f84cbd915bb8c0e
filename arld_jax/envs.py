"""Batched environments: MJX HalfCheetah through Brax, and a cheap pure-JAX stand-in for tests.

`make_env(cfg)` returns reset/step functions over a leading env axis. Time limits and resets are NOT
handled here: HalfCheetah never terminates, so every episode lasts exactly `cfg.episode_length` steps
and all envs of a run start and end together. The training loop therefore resets all envs at the
iteration that ends an episode, from fresh random initial states (Brax's AutoResetWrapper would
replay the first initial state forever), under a `lax.cond` whose predicate depends only on the
iteration index, so the reset costs nothing on the other 999 steps, also under `vmap` over seeds.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np

from arld_jax import gait
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
    upside_down: Callable[[jax.Array], jax.Array]  # obs [..., obs_dim] -> bool [...] (the gait)


def halfcheetah_upside_down(obs: jax.Array) -> jax.Array:
    """True where the HalfCheetah's torso is upside down (`gait.upside_down`)."""
    return gait.upside_down(obs, jnp)


def never_upside_down(obs: jax.Array) -> jax.Array:
    """The toy env has no body: never upside down."""
    return jnp.zeros(obs.shape[:-1], bool)


CPU_ENV_MAX_BATCH = 16
"""`env_max_batch = 0` (auto) means this many on CPU (measured: see `Config.env_max_batch`)."""


def make_env(cfg: Config) -> Env:
    """The batched env named by `cfg.env_name`, its vmapped step limited by `cfg.env_max_batch`."""
    env = _brax_env("halfcheetah", cfg.backend) if cfg.env_name == "halfcheetah" else _toy_env()
    max_batch = cfg.env_max_batch
    if max_batch == 0:  # auto: chunk on CPU only; accelerators want the widest batch
        max_batch = CPU_ENV_MAX_BATCH if jax.default_backend() == "cpu" else -1
    return env._replace(step=limit_batch(env.step, max_batch))


def limit_batch(step: Callable[[EnvState, jax.Array], EnvState], max_batch: int) -> Callable:
    """`step` (batched over a leading env axis), except that under `jax.vmap` (over runs) the vmapped
    axis is folded into the env axis and the envs are stepped `max_batch` at most at a time, chunk
    after chunk (`lax.map`). Without vmap, or with max_batch < 1, it is `step` itself.

    Why: on CPU, MJX's cost per env grows with the batch (80 envs step at about half the total rate
    of 5 x 16), while the rest of a vmapped sweep wants the widest batch. Chunk j holds envs j,
    j + num_chunks, j + 2 num_chunks, ... (strided), so when the run axis is sharded over devices
    every chunk keeps its share on each device. Chunks are padded by repeating envs; the padded
    results are dropped."""
    if max_batch < 1:
        return step

    @jax.custom_batching.custom_vmap
    def limited(state: EnvState, action: jax.Array) -> EnvState:
        return step(state, action)

    @limited.def_vmap
    def _rule(axis_size: int, in_batched: list, state: EnvState, action: jax.Array):  # noqa: ANN202
        args = jax.tree.map(
            lambda x, b: x if b else jnp.broadcast_to(x, (axis_size, *jnp.shape(x))),
            (state, action),
            tuple(in_batched),
        )
        n = action.shape[-2]  # envs per run
        total = axis_size * n
        num_chunks = -(-total // max_batch)
        size = -(-total // num_chunks)  # balanced chunks: 80 -> 5 x 16, 20 -> 2 x 10
        padded = num_chunks * size

        def flat(x: jax.Array) -> jax.Array:
            return x.reshape(total, *x.shape[2:])

        def unflat(x: jax.Array) -> jax.Array:
            return x.reshape(axis_size, n, *x.shape[1:])

        if num_chunks == 1:
            out = jax.tree.map(unflat, step(*jax.tree.map(flat, args)))
            return out, jax.tree.map(lambda _: True, out)

        def to_chunks(x: jax.Array) -> jax.Array:  # [total, ...] -> [num_chunks, size, ...]
            x = flat(x)
            if padded > total:  # pad by repeating envs
                x = x[jnp.arange(padded) % total]
            return jnp.swapaxes(x.reshape(size, num_chunks, *x.shape[1:]), 0, 1)

        def from_chunks(x: jax.Array) -> jax.Array:
            x = jnp.swapaxes(x, 0, 1).reshape(padded, *x.shape[2:])
            return unflat(x[:total])

        out = jax.lax.map(lambda a: step(*a), jax.tree.map(to_chunks, args))
        out = jax.tree.map(from_chunks, out)
        return out, jax.tree.map(lambda _: True, out)

    return limited


# Third-party messages that every run printed and no user can act on: MuJoCo-MJX's optional Warp
# backend is not installed (printed at import), Brax's notice that its envs are unmaintained (we
# keep Brax's halfcheetah on purpose, see README), MuJoCo's deprecation of the `settotalmass`
# attribute in Brax's half_cheetah.xml (printed by MuJoCo's C compiler).
_THIRD_PARTY_NOISE = (
    "Failed to import warp",
    "Failed to import mujoco_warp",
    "settotalmass",
    "not actively being maintained",
)


@contextlib.contextmanager
def without_third_party_noise() -> Iterator[None]:
    """Run the block with stdout/stderr captured at the file-descriptor level (MuJoCo's C code
    writes there directly), then re-print every captured line except `_THIRD_PARTY_NOISE`; an
    exception in the block re-prints everything, so nothing that explains an error is lost."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    with tempfile.TemporaryFile(mode="w+b") as capture, warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*not actively being maintained.*")
        failed = False
        try:
            for fd in (1, 2):
                os.dup2(capture.fileno(), fd)
            yield
        except BaseException:
            failed = True
            raise
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            for fd, copy in saved.items():
                os.dup2(copy, fd)
                os.close(copy)
            capture.seek(0)
            for line in capture.read().decode(errors="replace").splitlines():
                if line.strip() and (failed or not any(n in line for n in _THIRD_PARTY_NOISE)):
                    print(line, file=sys.stderr)


def _brax_env(name: str, backend: str) -> Env:
    with without_third_party_noise():
        # Imported lazily: the toy env and the unit tests do not need Brax.
        from brax import envs as brax_envs

        env = brax_envs.get_environment(name, backend=backend)

    def wrap(s: Any) -> EnvState:
        return EnvState(inner=s, obs=s.obs, reward=s.reward, terminated=s.done)

    def reset(key: PRNGKey, n: int) -> EnvState:
        return wrap(jax.vmap(env.reset)(jax.random.split(key, n)))

    def step(state: EnvState, action: jax.Array) -> EnvState:
        return wrap(jax.vmap(env.step)(state.inner, action))

    upside_down = halfcheetah_upside_down if name == "halfcheetah" else never_upside_down
    return Env(
        reset=reset,
        step=step,
        obs_dim=env.observation_size,
        action_dim=env.action_size,
        upside_down=upside_down,
    )


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

    return Env(
        reset=reset,
        step=step,
        obs_dim=_TOY_OBS_DIM,
        action_dim=_TOY_ACTION_DIM,
        upside_down=never_upside_down,
    )
