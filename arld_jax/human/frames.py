"""What the person sees of the state: frames of a task's bodies drawn from the simulator's geometry.

A frame is the side view (x-z plane) of the task's capsules and spheres, placed by MuJoCo's forward
kinematics (`mujoco.mj_kinematics`, host side, no GL) on the MjModel of Brax's own task, the model
both physics backends simulate. The pose comes from the observation (`TaskSpec.pose`: Brax leaves
the root's x, and for a 3D body its y, out of the observation, so they are set to 0 and the body is
drawn centred horizontally). A capsule seen from the side is a line of width 2r with round caps, a
sphere a dot of radius r (a line of length 0), which is how the page draws them. The knobs are
named after the actuators, or where the model leaves an actuator unnamed, after the joint it
drives ("_joint" dropped).

Paper A.3: "The screen shows the last recent states, which helps the user demonstrate more
appropriately according to the context": the page shows the last few frames.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path
from typing import Any

import numpy as np

HALFCHEETAH_NQ = 9  # rootx, rootz, rooty, six joints
HALFCHEETAH_OBS_QPOS = HALFCHEETAH_NQ - 1  # obs[:8] = qpos[1:]
VIEW_MARGIN = 0.35
"""Metres of sky above the tallest point of a task's body at qpos0, in its frames."""


def brax_halfcheetah_xml() -> Path:
    """Path of the MJCF that Brax's (and so MJX's) halfcheetah is built from."""
    spec = importlib.util.find_spec("brax")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("brax is not installed: it ships the HalfCheetah model")
    return Path(spec.submodule_search_locations[0]) / "envs" / "assets" / "half_cheetah.xml"


@functools.cache
def halfcheetah_model() -> Any:
    """The host-side MuJoCo model (built once; only kinematics are used)."""
    import mujoco

    from arld_jax.physics import without_third_party_noise

    with without_third_party_noise():  # MuJoCo's 'settotalmass' deprecation for Brax's XML
        return mujoco.MjModel.from_xml_path(str(brax_halfcheetah_xml()))


@functools.cache
def task_model(env_name: str) -> Any:
    """The MjModel of Brax's task `env_name` (built once; only kinematics are used)."""
    if env_name == "halfcheetah":
        return halfcheetah_model()
    from arld_jax.physics import load_brax_env
    from arld_jax.tasks import REGISTRY

    return load_brax_env(REGISTRY[env_name].brax_name, "mjx").sys.mj_model


def action_names(env_name: str) -> list[str]:
    """The task's actuator names in action order (HalfCheetah: bthigh, bshin, bfoot, fthigh,
    fshin, ffoot; Hopper: thigh, leg, foot; Ant: hip_4, ankle_4, hip_1, ...)."""
    model = task_model(env_name)
    names = []
    for i in range(model.nu):
        name = model.actuator(i).name or model.joint(model.actuator_trnid[i, 0]).name
        names.append(name.removesuffix("_joint"))
    return names


def halfcheetah_action_names() -> list[str]:
    """Actuator names in action order: bthigh, bshin, bfoot, fthigh, fshin, ffoot."""
    return action_names("halfcheetah")


def qpos_from_obs(obs: np.ndarray, x: float = 0.0) -> np.ndarray:
    """Brax halfcheetah observation -> qpos, with the unobserved torso x set to `x`."""
    obs = np.asarray(obs, np.float64)
    if obs.shape != (17,):
        raise ValueError(f"a HalfCheetah observation has 17 values, got shape {obs.shape}")
    return np.concatenate([[x], obs[:HALFCHEETAH_OBS_QPOS]])


def kinematics(qpos: np.ndarray, model: Any = None) -> Any:
    """MuJoCo forward kinematics of `model` (default HalfCheetah's) at `qpos` (an `MjData` with
    geom_xpos, geom_xmat)."""
    import mujoco

    model = halfcheetah_model() if model is None else model
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    return data


def body_segments(qpos: np.ndarray, model: Any = None) -> list[dict[str, Any]]:
    """Every capsule and sphere geom of `model` (default HalfCheetah's) at `qpos`, as the side-view
    segment it projects to: {name, x1, z1, x2, z2, r} in metres (a capsule's axis end points, a
    sphere's centre twice, and the radius)."""
    import mujoco

    model = halfcheetah_model() if model is None else model
    data = kinematics(qpos, model)
    out = []
    for g in range(model.ngeom):
        kind = model.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            half_length = float(model.geom_size[g, 1])
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            half_length = 0.0
        else:
            continue  # the floor plane is drawn by the page as the ground line
        centre = data.geom_xpos[g]
        axis = data.geom_xmat[g].reshape(3, 3)[:, 2]  # a capsule's axis is its local z
        a, b = centre - half_length * axis, centre + half_length * axis
        out.append(
            {
                "name": model.geom(g).name or model.body(model.geom_bodyid[g]).name,
                "x1": round(float(a[0]), 5),
                "z1": round(float(a[2]), 5),
                "x2": round(float(b[0]), 5),
                "z2": round(float(b[2]), 5),
                "r": float(model.geom_size[g, 0]),
            }
        )
    return out


capsule_segments = body_segments  # HalfCheetah's geoms are all capsules


def halfcheetah_frame(obs: np.ndarray) -> dict[str, Any]:
    """One frame of the page: the capsules at the observed pose, and the torso height and pitch."""
    obs = np.asarray(obs, np.float64)
    return {
        "segments": capsule_segments(qpos_from_obs(obs)),
        "rootz": float(obs[0]),
        "pitch": float(obs[1]),
        "vx": float(obs[HALFCHEETAH_OBS_QPOS]),
    }


@functools.cache
def view_top(env_name: str) -> float:
    """The height the task's frames show: its tallest point at qpos0 plus `VIEW_MARGIN`."""
    model = task_model(env_name)
    segments = body_segments(model.qpos0, model)
    return round(max(max(s["z1"], s["z2"]) + s["r"] for s in segments) + VIEW_MARGIN, 2)


def task_frame(env_name: str, obs: np.ndarray) -> dict[str, Any]:
    """One frame of the page for Brax's task `env_name`: its bodies at the observed pose, the
    torso's height, the forward speed, and the height to show (`view_top`)."""
    from arld_jax.tasks import REGISTRY

    if env_name == "halfcheetah":
        return halfcheetah_frame(obs)
    model = task_model(env_name)
    qpos, vx = REGISTRY[env_name].pose(np.asarray(obs, np.float64), model)
    segments = body_segments(qpos, model)
    torso = kinematics(qpos, model).xpos[1]
    return {"segments": segments, "rootz": float(torso[2]), "vx": vx, "top": view_top(env_name)}
