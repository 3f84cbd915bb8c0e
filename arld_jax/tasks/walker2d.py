"""Walker2d: Brax's `walker2d`, a planar two-legged walker; a fall ends the episode.

Brax's env object defines it (brax/envs/walker2d.py, brax 0.14.2; `arld_jax.physics` runs it on
both backends): 9 joints (root x, z, pitch; thigh, leg, foot hinges of each leg), 6 actuators (right
thigh, leg, foot, then left), 4 frames of 0.002 s per step; reset: qpos0 + U(-0.005, 0.005),
qvel ~ U(-0.005, 0.005); observation (17) = qpos[1:] with the root's z replaced by the torso's
height, then qvel clipped to [-10, 10]; reward = forward velocity of the torso + 1 (alive) -
0.001 |a|^2. Health rule (Brax's `done`): it fell when the torso's height leaves (0.8, 2.0) or its
pitch leaves (-1, 1).

Its observation and action have HalfCheetah's sizes (17, 6): only the task recorded with an
expert tells the two apart (`arld_jax.expert`).
"""

from __future__ import annotations

from arld_jax.tasks.base import TaskSpec, pose_with_height

SPEC = TaskSpec(
    name="walker2d",
    summary="Brax's Walker2d: a planar walker, ends when it falls (obs 17, action 6)",
    can_terminate=True,
    expert_dir="experiments/expert_walker2d",
    brax_name="walker2d",
    pose=pose_with_height,
)
