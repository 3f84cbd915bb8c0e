"""Is the peer's env arld_jax's? Steps one task in both from the same states and actions.

Two halves, each in its own python. `dump` (the project's python) plays uniform-random actions in
arld_jax's task on MuJoCo's C engine and writes, per step, the physics state it started from
(qpos, qvel, the solver's warm start), the action and what the step returned (observation,
reward, termination), and the state of 256 resets. `check` (the sbx venv's python, the model
flags of `sbx_sac.py`) puts Gymnasium's env into each recorded state, takes the recorded action
and prints the largest differences; it exits with 1 if the observation
or reward (at a step that ends no episode) differs beyond float32's rounding of arld_jax's state (`--atol`):

    python -m benchmarks.peers.same_model dump --task ant --out /tmp/ant_steps.npz
        [--xml-out ant.xml]    (also the model as Brax loads it, for the peer's --xml-file)
    ../venv-sbx/bin/python -m benchmarks.peers.same_model check --steps /tmp/ant_steps.npz \\
        --env Ant-v5 --xml-file ... (the model flags of the run it vouches for)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def dump(
    task: str, out: str, episodes: int, max_steps: int, seed: int, xml_out: str | None
) -> None:
    import jax

    from arld_jax.config import Config
    from arld_jax.envs import make_env
    from arld_jax.tasks import BRAX_TASKS

    if task not in BRAX_TASKS:
        sys.exit(f"--task {task}: not a Brax task; allowed {sorted(BRAX_TASKS)}")
    if xml_out:
        write_model_xml(task, xml_out)
    env = make_env(Config(env_name=task, backend="mujoco"))
    reset, step = jax.jit(env.reset, static_argnums=1), jax.jit(env.step)
    rng = np.random.default_rng(seed)
    keys = ("q", "qd", "warm", "xpos", "action", "obs", "reward", "done")
    rows: dict[str, list] = {k: [] for k in keys}
    for e in range(episodes):
        s = reset(jax.random.key(e), 1)
        for _ in range(max_steps):
            ps = s.inner.pipeline_state
            a = rng.uniform(-1.0, 1.0, (1, env.action_dim)).astype(np.float32)
            rows["q"].append(np.asarray(ps.q[0]))
            rows["qd"].append(np.asarray(ps.qd[0]))
            rows["warm"].append(np.asarray(ps.qacc_warmstart[0]))
            rows["xpos"].append(np.asarray(ps.x.pos[0]))  # [bodies, 3]
            s = step(s, a)
            rows["action"].append(a[0])
            rows["obs"].append(np.asarray(s.obs[0]))
            rows["reward"].append(np.asarray(s.reward[0]))
            rows["done"].append(np.asarray(s.terminated[0]))
            if bool(s.terminated[0]):
                break
    resets = reset(jax.random.key(seed + 1), 256).inner.pipeline_state
    np.savez(
        out,
        **{k: np.stack(v) for k, v in rows.items()},
        reset_q=np.asarray(resets.q),
        reset_qd=np.asarray(resets.qd),
    )
    print(f"{out}: {len(rows['q'])} steps of {task} in {episodes} episodes")


def write_model_xml(task: str, path: str) -> None:
    """The MJCF of the model arld_jax's task steps, as Brax loaded it (its jointless bodies fused:
    Ant's 13 bodies become 9), for a peer's `--xml-file`. Written by MuJoCo from the XML it last
    parsed, Brax's, right after loading it; reloaded and compared before it is kept. The options
    Brax sets on `sys` after loading (Ant's solver) are not in it: the peer takes them as
    `--model-opt`."""
    import mujoco

    from arld_jax.physics import load_brax_env
    from arld_jax.tasks import REGISTRY

    model = load_brax_env(REGISTRY[task].brax_name, "mjx").sys.mj_model
    mujoco.mj_saveLastXML(path, model)
    back = mujoco.MjModel.from_xml_path(path)
    if (back.nbody, back.nq, back.ngeom) != (model.nbody, model.nq, model.ngeom) or not np.allclose(
        back.body_mass, model.body_mass, rtol=1e-5
    ):
        Path(path).unlink()
        sys.exit(f"--xml-out {path}: MuJoCo's saved XML does not reload as {task}'s model")
    print(f"{path}: {task}'s model as Brax loads it ({model.nbody - 1} bodies)")


def check(p: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    from sbx_sac import env_maker  # the same env the peer's run makes (on the path: `main`)

    make, record = env_maker(p, args)
    env = make().unwrapped
    d = np.load(args.steps)
    obs_err, rew_err, done_diff, end_rew = 0.0, 0.0, 0, []
    for i in range(len(d["q"])):
        env.set_state(d["q"][i].astype(np.float64), d["qd"][i].astype(np.float64))
        env.data.qacc_warmstart[:] = d["warm"][i]
        # Brax's reward reads the torso's frame as the previous step left it, MuJoCo's xpos after
        # mj_step (computed before its last integration); set_state recomputed it. (Brax fuses
        # the jointless bodies, so only the torso, body 1, is body 1 in both.)
        env.data.xpos[1] = d["xpos"][i][0]
        obs, reward, terminated, _, _ = env.step(d["action"][i].astype(np.float64))
        obs_err = max(obs_err, float(np.max(np.abs(obs - d["obs"][i]))))
        if d["done"][i] or terminated:
            end_rew.append(float(d["reward"][i]) - float(reward))
        else:
            rew_err = max(rew_err, abs(float(reward) - float(d["reward"][i])))
        done_diff += int(bool(terminated) != bool(d["done"][i]))
    init_err = float(np.max(np.abs(d["reset_q"].mean(0) - env.init_qpos)))
    vel_err = float(np.max(np.abs(d["reset_qd"].mean(0) - env.init_qvel)))
    print(f"model: {record}")
    print(f"{len(d['q'])} steps ({int(d['done'].sum())} ending by a fall):")
    print(f"  largest |observation difference| {obs_err:.2e}")
    print(f"  largest |reward difference|      {rew_err:.2e} (steps that end no episode)")
    print(f"  arld_jax's - Gymnasium's reward at a step that ends one: {np.round(end_rew, 3)}")
    print(f"  steps whose termination differs  {done_diff}")
    print(f"  mean reset qpos - Gymnasium's init_qpos, largest |.| {init_err:.3f} (256 resets)")
    print(f"  mean reset qvel - Gymnasium's init_qvel, largest |.| {vel_err:.3f}")
    # qpos resets add uniform noise of half-width 0.1: the mean of 256 lies within about 0.015 of
    # the centre (4 standard deviations); another initial pose is off by far more (Gymnasium's
    # own Ant: 1.0).
    same = obs_err <= args.atol and rew_err <= args.atol and init_err < 0.03
    print("same model" if same else "NOT the same model")
    return 0 if same else 1


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="half", required=True)
    pd = sub.add_parser("dump", help="arld_jax's steps (the project's python)")
    pd.add_argument("--task", required=True)
    pd.add_argument("--out", required=True)
    pd.add_argument("--episodes", type=int, default=5)
    pd.add_argument("--max-steps", type=int, default=300)
    pd.add_argument("--seed", type=int, default=0)
    pd.add_argument("--xml-out", help="also write the task's model, as Brax loads it, to this MJCF")
    pc = sub.add_parser("check", help="Gymnasium's steps from the same states (the sbx venv)")
    pc.add_argument("--steps", required=True, help="the .npz `dump` wrote")
    pc.add_argument("--atol", type=float, default=1e-3)
    sys.path.insert(0, str(Path(__file__).parent))
    from sbx_sac import add_model_args

    add_model_args(pc)
    args = p.parse_args(argv)
    if args.half == "dump":
        dump(args.task, args.out, args.episodes, args.max_steps, args.seed, args.xml_out)
    else:
        sys.exit(check(pc, args))


if __name__ == "__main__":
    main()
