"""The env interface the training loop steps, and what a task module declares.

An env is a bundle of pure functions over a leading env axis (`Env`): `reset(key, n)` gives n fresh
random initial states, `step(state, action)` the true next states with their rewards and whether
each env fell (`terminated`, the task's health rule). Time limits are not the env's job: the loop
truncates episodes at `Config.episode_length` and resets envs itself.

A task is one module of `arld_jax.tasks` with a `SPEC = TaskSpec(...)`; `arld_jax.tasks.REGISTRY`
finds it, `Config.env_name`'s choices, the shipped expert's path and `envs.make_env` derive from it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np

from arld_jax.types import PRNGKey


@flax.struct.dataclass
class EnvState:
    """A batch of environment states. `obs` after a step is the true next observation."""

    inner: Any  # backend state (Brax State, or the toy env's state vector)
    obs: jax.Array  # [num_envs, obs_dim]
    reward: jax.Array  # [num_envs]
    terminated: jax.Array  # [num_envs] float32: 1 where the step ended in a fall (health rule)


class Env(NamedTuple):
    reset: Callable[[PRNGKey, int], EnvState]  # (key, n) -> n fresh random initial states
    step: Callable[[EnvState, jax.Array], EnvState]  # (state [n], action [n, A]) -> state [n]
    obs_dim: int
    action_dim: int
    upside_down: Callable[[jax.Array], jax.Array]  # obs [..., obs_dim] -> bool [...] (the gait)
    can_terminate: bool = False  # static: whether `step` can ever set `terminated` (a fall)


def select_envs(mask: jax.Array, a: Any, b: Any) -> Any:
    """`a` for the envs where `mask` [E] is set, `b` for the others, leaf by leaf (every leaf of an
    EnvState leads with the env axis): a fresh state for envs that ended, a frozen one for ended
    evaluation episodes."""
    return jax.tree.map(
        lambda x, y: jnp.where(mask.reshape(mask.shape + (1,) * (y.ndim - 1)), x, y), a, b
    )


def never_upside_down(obs: jax.Array) -> jax.Array:
    """Tasks without HalfCheetah's gait rule: never upside down."""
    return jnp.zeros(obs.shape[:-1], bool)


Pose = Callable[[np.ndarray, Any], tuple[np.ndarray, float]]
"""(observation, the task's MjModel) -> (qpos to draw, forward speed): what the demonstration
page draws of a state (`arld_jax.human.frames`). The root's unobserved x (and y) are set to 0, so
the body is drawn centred."""


def pose_after_root_x(obs: np.ndarray, model: Any) -> tuple[np.ndarray, float]:
    """Brax's planar observation qpos[1:], qvel (HalfCheetah)."""
    k = model.nq - 1
    return np.concatenate([[0.0], obs[:k]]), float(obs[k])


def pose_with_height(obs: np.ndarray, model: Any) -> tuple[np.ndarray, float]:
    """Brax's planar observation with the torso's height in place of the root's z slide (Hopper,
    Walker2d): the slide is the height less the torso's height at qpos0. (Brax observes the height
    as of the step's last physics frame's start, so after a step the drawn height lags by one
    frame, 2 ms of motion.)"""
    k = model.nq - 1
    qpos = np.concatenate([[0.0], obs[:k]])
    qpos[1] = obs[0] - model.body_pos[1, 2]
    return qpos, float(obs[k])


def pose_after_root_xy(obs: np.ndarray, model: Any) -> tuple[np.ndarray, float]:
    """Brax's observation of a free root, qpos[2:], qvel, ... (Ant, Humanoid)."""
    k = model.nq - 2
    return np.concatenate([[0.0, 0.0], obs[:k]]), float(obs[k])


@dataclass(frozen=True)
class TaskSpec:
    """Everything the rest of the package knows of a task before building it.

    A Brax task names Brax's env (`brax_name`) and takes its model, reset distribution,
    observation, reward and health rule from it on every backend (`arld_jax.physics`); a pure-JAX
    stand-in of the tests gives its own `make_pure` and ignores the backend."""

    name: str
    """`Config.env_name`."""
    summary: str
    """One line for help texts: what the body is and what ends its episodes."""
    can_terminate: bool
    """Whether an episode can end early (a fall). Checked against Brax's env when it is built."""
    expert_dir: str | None = None
    """Where the task's expert is shipped, relative to the repository root (the default
    `--expert_path`, and `train_expert`'s default `--out`); the task has a shipped expert when an
    expert is there. None: the task needs no saved expert (`target_action` is its expert)."""
    brax_name: str | None = None
    """Brax's name of the task (`brax.envs.get_environment`)."""
    upside_down: Callable[[jax.Array], jax.Array] = never_upside_down
    """The gait rule (HalfCheetah's flipped torso); other tasks: never upside down."""
    reads_velocities: bool = False
    """Whether Brax's task reads the bodies' velocities (`xd`: Humanoid's observation); the others
    read q, qd and the bodies' frames only, and the C engine returns no more (`physics`)."""
    contact_forces: bool = False
    """Whether the task also observes, and pays for, the external contact force on each body, as
    Gymnasium's Ant-v5 does and Brax's Ant documents but leaves out (brax 0.14.2 refuses its
    `use_contact_forces=True`): the observation gains cfrc_ext[1:] (6 per body: torque then force about
    the centre of mass, every body but the world), clipped to Brax's `contact_force_range`, and the
    reward loses Brax's `contact_cost_weight` x the sum of their squares (`physics`)."""
    pose: Pose | None = None
    """How the demonstration page draws a state (a Brax task's); None: the page shows numbers."""
    make_pure: Callable[[], Env] | None = None
    """A pure-JAX task's env (no physics: the same on every backend)."""
    target_action: Callable[[jax.Array], jax.Array] | None = None
    """A pure-JAX task's best action, known in closed form: its expert."""

    @property
    def has_gait_rule(self) -> bool:
        """Whether the task has a gait rule (`upside_down`): the upside-down share is reported
        for these tasks only."""
        return self.upside_down is not never_upside_down

    def make(
        self, backend: str, options: dict[str, int] | None = None, contacts: str = "task"
    ) -> Env:
        """The batched env on `backend` ('mjx', 'mujoco', or one of Brax's own pipelines), with
        MuJoCo's options `options` (`opt.*` name -> value: the solver's, the integrator) over the
        task's own and the contacts `contacts` (`Config.contacts`)."""
        if self.make_pure is not None:
            return self.make_pure()
        from arld_jax import physics

        return physics.brax_task_env(self, backend, options, contacts)
