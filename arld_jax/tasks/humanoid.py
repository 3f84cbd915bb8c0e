"""Humanoid: Brax's `humanoid`, a 3D biped that runs along x; a fall ends the episode.

Brax's env object defines it (brax/envs/humanoid.py, brax 0.14.2; `arld_jax.physics` runs it on
both backends): a free root and 17 hinges, 17 actuators (actions in [-1, 1] scaled by Brax to the
actuators' control range), 5 frames of 0.003 s per step, and for MJX (so also for the C engine
here) Newton's solver with 1 iteration and 4 line searches; reset: qpos0 + U(-0.01, 0.01),
qvel ~ U(-0.01, 0.01); observation (244) = qpos[2:], qvel, the bodies' inertias and
centre-of-mass velocities about the whole body's centre of mass, and the actuator forces; reward =
1.25 x velocity of the centre of mass + 5 (alive) - 0.1 |scaled a|^2. Health rule (Brax's `done`):
it fell when the torso's height leaves [1.0, 2.0]. The only task whose observation reads the
bodies' velocities (`reads_velocities`).
"""

from __future__ import annotations

from arld_jax.tasks.base import TaskSpec, pose_after_root_xy

SPEC = TaskSpec(
    name="humanoid",
    summary="Brax's Humanoid: a biped in 3D, ends when it falls (obs 244, action 17)",
    can_terminate=True,
    expert_dir="experiments/expert_humanoid",
    brax_name="humanoid",
    pose=pose_after_root_xy,
    reads_velocities=True,
)
