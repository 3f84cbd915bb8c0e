"""Ant: Brax's `ant`, a four-legged body in 3D that runs along x; a fall ends the episode.

Brax's env object defines it (brax/envs/ant.py, brax 0.14.2; `arld_jax.physics` runs it on both
backends): a free root (position and quaternion) and 8 hinges (hip and ankle of each leg), 8
actuators, 5 frames of 0.01 s per step, and for MJX (so also for the C engine here) Newton's
solver with 1 iteration and 4 line searches; reset: qpos0 + U(-0.1, 0.1), qvel ~ 0.1 N(0, 1);
observation (27) = qpos[2:] (the root's x and y left out) then qvel, no contact forces; reward =
x velocity of the torso + 1 (alive) - 0.5 |a|^2. Health rule (Brax's `done`): it fell when the
torso's height leaves [0.2, 1.0] (flipped over or jumped).
"""

from __future__ import annotations

from arld_jax.tasks.base import TaskSpec, pose_after_root_xy

SPEC = TaskSpec(
    name="ant",
    summary="Brax's Ant: a quadruped in 3D, ends when it falls (obs 27, action 8)",
    can_terminate=True,
    expert_dir="experiments/expert_ant",
    brax_name="ant",
    pose=pose_after_root_xy,
)
