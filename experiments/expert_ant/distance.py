"""How far the shipped Ant expert moves: 10 deterministic episodes on the C engine, each from a
fresh random initial state (key 777), with each episode's return split into Brax's Ant terms.

    python experiments/expert_ant/distance.py > experiments/expert_ant/distance.txt

Brax's Ant pays, per step, the torso's x velocity + 1 (alive) - 0.5 |a|^2 (control; no contact
cost), so over an episode: sum of x velocities = return - steps + control cost, and the distance
along x = that sum x dt (0.05 s per step).
"""

import jax
import jax.numpy as jnp
import numpy as np

from arld_jax.config import Config
from arld_jax.envs import make_env
from arld_jax.evaluate import rollout
from arld_jax.expert import load_expert
from arld_jax.sweep import expert_path_for

EPISODES, LENGTH, DT = 10, 1000, 0.05

cfg = Config(env_name="ant", backend="mujoco")
env = make_env(cfg)
expert = load_expert(expert_path_for(cfg), env.obs_dim, env.action_dim, env_name="ant")
policy = lambda obs: expert.act(expert.params, obs, jax.random.key(0))  # noqa: E731 (tanh(mu))


def control_cost_step(state, action):
    """The task's step, its reward replaced by the control cost it charged, 0.5 |a|^2."""
    return env.step(state, action).replace(reward=0.5 * jnp.sum(action**2, -1))


# The same key, the same deterministic policy: the same episodes, summed twice.
key = jax.random.key(777)
played = jax.jit(lambda k: rollout(env, policy, k, EPISODES, LENGTH))(key)
charged = jax.jit(
    lambda k: rollout(env._replace(step=control_cost_step), policy, k, EPISODES, LENGTH)
)(key)
ret, steps, ctrl = (
    np.asarray(x) for x in (played.episode_return, played.length, charged.episode_return)
)
forward = ret - steps + ctrl
for name, values in [
    ("return", ret),
    ("steps", steps),
    ("control cost", ctrl),
    ("sum of x velocities", forward),
    ("distance along x, m", forward * DT),
]:
    print(f"{name:>20}: " + " ".join(f"{v:7.1f}" for v in values))
