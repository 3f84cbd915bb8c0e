"""The shipped Ant expert under Brax's contact solver and under MuJoCo's default one: the 10
episodes of `distance.py` (C engine, the same fresh initial states), once with Ant's own solver
options (Newton, 1 iteration, 4 line searches) and once with MuJoCo's defaults (100 iterations,
50 line searches, as Gymnasium's Ant-v5 runs them).

    python experiments/expert_ant/solver.py > experiments/expert_ant/solver.txt
"""

import numpy as np
from distance import expert_episodes

from arld_jax.config import Config

for name, iterations, ls_iterations in (("Brax's (1, 4)", 0, 0), ("MuJoCo's (100, 50)", 100, 50)):
    cfg = Config(
        env_name="ant",
        backend="mujoco",
        solver_iterations=iterations,
        solver_ls_iterations=ls_iterations,
    )
    played = expert_episodes(cfg)
    ret, steps = np.asarray(played.episode_return), np.asarray(played.length)
    print(f"{name:>20} return: " + " ".join(f"{v:6.0f}" for v in ret))
    print(f"{name:>20}  steps: " + " ".join(f"{v:6.0f}" for v in steps))
