"""HalfCheetah: Brax's `halfcheetah`, a planar two-legged body that runs forward and never falls.

Brax's env object defines it (brax/envs/half_cheetah.py, brax 0.14.2; `arld_jax.physics` runs it
on both backends): 9 joints (root x, z, pitch and six leg hinges), 6 actuators (back and front
thigh, shin, foot), 5 frames of 0.01 s per step; reset: qpos0 + U(-0.1, 0.1), qvel ~ 0.1 N(0, 1);
observation (17) = qpos[1:] (the root's x left out) then qvel; reward = forward velocity of the
torso - 0.1 |a|^2. No health rule: an episode ends only at the time limit. What goes wrong
instead is the gait: running on its back, a well-known local optimum of SAC here
(`arld_jax.gait`), counted by `Env.upside_down`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from arld_jax import gait
from arld_jax.tasks.base import TaskSpec, pose_after_root_x


def halfcheetah_upside_down(obs: jax.Array) -> jax.Array:
    """True where the HalfCheetah's torso is upside down (`gait.upside_down`)."""
    return gait.upside_down(obs, jnp)


SPEC = TaskSpec(
    name="halfcheetah",
    summary="Brax's HalfCheetah: a planar runner, never falls (obs 17, action 6)",
    can_terminate=False,
    expert_dir="experiments/expert",
    brax_name="halfcheetah",
    pose=pose_after_root_x,
    upside_down=halfcheetah_upside_down,
)
