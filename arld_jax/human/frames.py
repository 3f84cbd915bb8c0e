"""What the person sees of the state: HalfCheetah frames drawn from the simulator's own geometry.

A frame is the side view (x-z plane) of the HalfCheetah's capsules, placed by MuJoCo's forward
kinematics (`mujoco.mj_kinematics`, host side, no GL) on Brax's own `half_cheetah.xml`, the model
MJX simulates. Brax observes qpos[1:] then qvel (the torso's x position is left out), so
qpos = [0, obs[:8]]: the frame is the simulated pose exactly, centred on the torso horizontally.
A capsule seen from the side is a line of width 2r with round caps, which is how the page draws it.

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

    from arld_jax.envs import without_third_party_noise

    with without_third_party_noise():  # MuJoCo's 'settotalmass' deprecation for Brax's XML
        return mujoco.MjModel.from_xml_path(str(brax_halfcheetah_xml()))


def halfcheetah_action_names() -> list[str]:
    """Actuator names in action order: bthigh, bshin, bfoot, fthigh, fshin, ffoot."""
    model = halfcheetah_model()
    return [model.actuator(i).name for i in range(model.nu)]


def qpos_from_obs(obs: np.ndarray, x: float = 0.0) -> np.ndarray:
    """Brax halfcheetah observation -> qpos, with the unobserved torso x set to `x`."""
    obs = np.asarray(obs, np.float64)
    if obs.shape != (17,):
        raise ValueError(f"a HalfCheetah observation has 17 values, got shape {obs.shape}")
    return np.concatenate([[x], obs[:HALFCHEETAH_OBS_QPOS]])


def kinematics(qpos: np.ndarray) -> Any:
    """MuJoCo forward kinematics of the model at `qpos` (an `MjData` with geom_xpos, geom_xmat)."""
    import mujoco

    model = halfcheetah_model()
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    return data


def capsule_segments(qpos: np.ndarray) -> list[dict[str, Any]]:
    """Every capsule geom of the model at `qpos`, as the side-view segment it projects to:
    {name, x1, z1, x2, z2, r} in metres (the capsule's axis end points and its radius)."""
    import mujoco

    model = halfcheetah_model()
    data = kinematics(qpos)
    out = []
    for g in range(model.ngeom):
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_CAPSULE:
            continue  # the floor plane is drawn by the page as the ground line
        radius, half_length = float(model.geom_size[g, 0]), float(model.geom_size[g, 1])
        centre = data.geom_xpos[g]
        axis = data.geom_xmat[g].reshape(3, 3)[:, 2]  # a capsule's axis is its local z
        a, b = centre - half_length * axis, centre + half_length * axis
        out.append(
            {
                "name": model.geom(g).name,
                "x1": round(float(a[0]), 5),
                "z1": round(float(a[2]), 5),
                "x2": round(float(b[0]), 5),
                "z2": round(float(b[2]), 5),
                "r": radius,
            }
        )
    return out


def halfcheetah_frame(obs: np.ndarray) -> dict[str, Any]:
    """One frame of the page: the capsules at the observed pose, and the torso height and pitch."""
    obs = np.asarray(obs, np.float64)
    return {
        "segments": capsule_segments(qpos_from_obs(obs)),
        "rootz": float(obs[0]),
        "pitch": float(obs[1]),
        "vx": float(obs[HALFCHEETAH_OBS_QPOS]),
    }
