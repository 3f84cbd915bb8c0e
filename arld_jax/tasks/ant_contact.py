"""Ant with its contact forces: Brax's `ant` (`arld_jax.tasks.ant`) that also observes the
external contact force on each of its 9 bodies and pays for them, as Gymnasium's Ant-v5 does.

The body, its physics, reset, health rule and the rest of the reward are Brax's Ant's, read from
the same env object. What `TaskSpec.contact_forces` adds (`arld_jax.physics`, both backends): the
observation (81) = Brax's Ant's 27, then cfrc_ext[1:] clipped to [-1, 1] (54: torque and force
about each body's centre of mass, after the step's last physics frame's forward pass, as MuJoCo's
`mj_rnePostConstraint` and MJX's `rne_postconstraint` compute them); the reward loses
5e-4 x the sum of their squares (at most 0.027 per step). Gymnasium's Ant-v5 observes 78 forces, of 13
bodies: Brax loads its XML's 13 with MuJoCo's compiler fusing each leg's jointless first segment
into the torso, leaving 9. Brax's Ant documents both terms with
these weights and leaves them unimplemented; Gymnasium's Ant-v5 has them on by default.

Why a task of its own: on Brax's Ant (27 observations, no contact terms) SAC, ours and sbx's
alike, learned to stand at 300k steps, while sbx's SAC on Gymnasium's full Ant-v5 learned to run
(experiments/README.md, the Ant section).
"""

from __future__ import annotations

from arld_jax.tasks.base import TaskSpec, pose_after_root_xy

SPEC = TaskSpec(
    name="ant_contact",
    summary="Brax's Ant observing and paying for its contact forces, as Gymnasium's Ant-v5 "
    "(obs 81, action 8)",
    can_terminate=True,
    expert_dir="experiments/expert_ant_contact",
    brax_name="ant",
    pose=pose_after_root_xy,
    contact_forces=True,
)
