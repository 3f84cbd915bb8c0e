"""The HalfCheetah's gait: is the torso upside down? Written once for JAX and NumPy arrays.

Brax's halfcheetah observes qpos[1:] then qvel, and qpos = (rootx, rootz, rooty, joints...), so
obs[..., 1] is the root's pitch angle (rooty, a hinge: unbounded, hence the wrap). Running on its
back ("the flipped cheetah") is a well-known local optimum of SAC on this task; a run that learns
it has most of its visited states upside down. No JAX import: `summary.py` uses it on saved arrays.
"""

from __future__ import annotations

from typing import Any

import numpy as np

HALFCHEETAH_PITCH_INDEX = 1
"""Index of the root's pitch angle in Brax's halfcheetah observation."""

LATE_FRACTION = 0.3
"""The gait is judged on the last 30% of training (late in training, where a flipped gait has settled)."""


def upside_down(obs: Any, xp: Any = np) -> Any:
    """True where |pitch| > pi/2 with the pitch wrapped to (-pi, pi]; obs [..., obs_dim] -> [...].
    `xp` is the array namespace (numpy, or jax.numpy inside a compiled program)."""
    pitch = obs[..., HALFCHEETAH_PITCH_INDEX]
    wrapped = xp.arctan2(xp.sin(pitch), xp.cos(pitch))
    return xp.abs(wrapped) > xp.pi / 2
