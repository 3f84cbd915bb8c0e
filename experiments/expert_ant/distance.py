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


def expert_episodes(cfg: Config, reward=None):  # noqa: ANN001, ANN201
    """The shipped Ant expert's deterministic episodes (tanh(mu)) from the fresh initial states of
    key 777 in the physics of `cfg`; `reward(state, action)`, if given, replaces the step's reward
    (the same episodes, another sum)."""
    env = make_env(cfg)
    if reward is not None:
        step = env.step
        env = env._replace(step=lambda s, a: step(s, a).replace(reward=reward(s, a)))
    expert = load_expert(expert_path_for(cfg), env.obs_dim, env.action_dim, env_name="ant")
    policy = lambda obs: expert.act(expert.params, obs, jax.random.key(0))  # noqa: E731
    return jax.jit(lambda k: rollout(env, policy, k, EPISODES, LENGTH))(jax.random.key(777))


if __name__ == "__main__":
    cfg = Config(env_name="ant", backend="mujoco")
    played = expert_episodes(cfg)
    charged = expert_episodes(cfg, reward=lambda s, a: 0.5 * jnp.sum(a**2, -1))  # control cost
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
