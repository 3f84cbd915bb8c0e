"""The shipped Ant expert under Brax's contact solver and under MuJoCo's default one: 10
deterministic episodes on the C engine from the same fresh initial states (key 777), once with
Ant's own solver options (Newton, 1 iteration, 4 line searches) and once with MuJoCo's defaults
(100 iterations, 50 line searches, as Gymnasium's Ant-v5 runs them).

    python experiments/expert_ant/solver.py > experiments/expert_ant/solver.txt
"""

import jax
import numpy as np

from arld_jax.config import Config
from arld_jax.envs import make_env
from arld_jax.evaluate import rollout
from arld_jax.expert import load_expert
from arld_jax.sweep import expert_path_for

EPISODES, LENGTH = 10, 1000

for name, iterations, ls_iterations in (("Brax's (1, 4)", 0, 0), ("MuJoCo's (100, 50)", 100, 50)):
    cfg = Config(
        env_name="ant",
        backend="mujoco",
        solver_iterations=iterations,
        solver_ls_iterations=ls_iterations,
    )
    env = make_env(cfg)
    expert = load_expert(expert_path_for(cfg), env.obs_dim, env.action_dim, env_name="ant")
    policy = lambda obs, e=expert: e.act(e.params, obs, jax.random.key(0))  # noqa: E731 (tanh(mu))
    played = jax.jit(lambda k, p=policy, v=env: rollout(v, p, k, EPISODES, LENGTH))(
        jax.random.key(777)
    )
    ret, steps = np.asarray(played.episode_return), np.asarray(played.length)
    print(f"{name:>20} return: " + " ".join(f"{v:6.0f}" for v in ret))
    print(f"{name:>20}  steps: " + " ".join(f"{v:6.0f}" for v in steps))
