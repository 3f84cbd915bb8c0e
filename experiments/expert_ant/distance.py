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
from arld_jax.expert import load_expert
from arld_jax.sweep import expert_path_for
from arld_jax.tasks.base import select_envs

EPISODES, LENGTH, DT = 10, 1000, 0.05

cfg = Config(env_name="ant", backend="mujoco")
env = make_env(cfg)
expert = load_expert(expert_path_for(cfg), env.obs_dim, env.action_dim, env_name="ant")


def step(carry, _):
    state, alive = carry
    action = expert.act(expert.params, state.obs, jax.random.key(0))  # deterministic: tanh(mu)
    nxt = env.step(state, action)
    reward = jnp.where(alive, nxt.reward, 0.0)
    ctrl = jnp.where(alive, 0.5 * jnp.sum(action**2, -1), 0.0)
    nxt = select_envs(alive, nxt, state)  # an episode that ended stays frozen, as in evaluation
    return (nxt, alive & ~(nxt.terminated > 0)), (reward, ctrl, alive)


@jax.jit
def episodes(key):
    carry = (env.reset(key, EPISODES), jnp.ones(EPISODES, bool))
    _, (reward, ctrl, alive) = jax.lax.scan(step, carry, None, length=LENGTH)
    return reward.sum(0), ctrl.sum(0), alive.sum(0)


ret, ctrl, steps = map(np.asarray, episodes(jax.random.key(777)))
forward = ret - steps + ctrl
for name, values in [
    ("return", ret),
    ("steps", steps),
    ("control cost", ctrl),
    ("sum of x velocities", forward),
    ("distance along x, m", forward * DT),
]:
    print(f"{name:>20}: " + " ".join(f"{v:7.1f}" for v in values))
