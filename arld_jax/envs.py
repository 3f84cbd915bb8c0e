"""Batched environments by name: `make_env(cfg)` builds the task `cfg.env_name` (a module of
`arld_jax.tasks`) on the physics `cfg.backend` (`arld_jax.physics`) with the MuJoCo options
(solver, integrator) and contacts of `cfg` (`config.model_options`, `Config.contacts`), its vmapped
step chunked by `cfg.env_max_batch`.

The env interface (`Env`, `EnvState`) is `arld_jax.tasks.base`'s; the names the rest of the
package imports from here are kept here. Time limits and resets are not the env's job: the loop
truncates episodes at `cfg.episode_length` and resets envs from fresh random initial states itself
(never Brax's AutoResetWrapper, which would replay the first initial state forever).
"""

from __future__ import annotations

import jax

from arld_jax.config import Config, model_options
from arld_jax.physics import CPU_ENV_MAX_BATCH, limit_batch, without_third_party_noise
from arld_jax.tasks import REGISTRY
from arld_jax.tasks.base import Env, EnvState, never_upside_down
from arld_jax.tasks.halfcheetah import halfcheetah_upside_down
from arld_jax.tasks.toy import toy_target_action
from arld_jax.tasks.toy_fall import TOY_FALL_ERROR


def make_env(cfg: Config) -> Env:
    """The batched env named by `cfg.env_name`, its vmapped step limited by `cfg.env_max_batch`."""
    env = REGISTRY[cfg.env_name].make(cfg.backend, model_options(cfg), cfg.contacts)
    if cfg.backend == "mujoco" and REGISTRY[cfg.env_name].brax_name is not None:
        return env  # a host loop: no chunking to tune
    max_batch = cfg.env_max_batch
    if max_batch == 0:  # auto: chunk on CPU only; accelerators want the widest batch
        max_batch = CPU_ENV_MAX_BATCH if jax.default_backend() == "cpu" else -1
    return env._replace(step=limit_batch(env.step, max_batch))


__all__ = [
    "CPU_ENV_MAX_BATCH",
    "TOY_FALL_ERROR",
    "Env",
    "EnvState",
    "halfcheetah_upside_down",
    "limit_batch",
    "make_env",
    "never_upside_down",
    "toy_target_action",
    "without_third_party_noise",
]
