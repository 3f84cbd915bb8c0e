"""Hopper: Brax's `hopper`, a planar one-legged body that hops forward; a fall ends the episode.

Brax's env object defines it (brax/envs/hopper.py, brax 0.14.2; `arld_jax.physics` runs it on
both backends): 6 joints (root x, z, pitch; thigh, leg, foot hinges), 3 actuators (thigh, leg,
foot), 4 frames of 0.002 s per step; reset: qpos0 + U(-0.005, 0.005), qvel ~ U(-0.005, 0.005);
observation (11) = qpos[1:] with the root's z replaced by the torso's height, then qvel clipped to
[-10, 10]; reward = forward velocity of the torso + 1 (alive) - 0.001 |a|^2. Health rule (Brax's
`done`): it fell when the torso's height is <= 0.7, its pitch is outside (-0.2, 0.2) or any of
qpos[2:], qvel is outside (-100, 100).
"""

from __future__ import annotations

from arld_jax.tasks.base import TaskSpec, pose_with_height

SPEC = TaskSpec(
    name="hopper",
    summary="Brax's Hopper: a planar hopper, ends when it falls (obs 11, action 3)",
    can_terminate=True,
    expert_dir="experiments/expert_hopper",
    brax_name="hopper",
    pose=pose_with_height,
)
