"""Expert save / load: round trip, deterministic acting, clear errors for missing or misfit experts."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from arld_jax.expert import load_expert, save_expert
from arld_jax.networks import Actor, deterministic_action


def _actor_and_params(obs_dim=4, action_dim=2, hidden=(8, 8)):
    actor = Actor(action_dim=action_dim, hidden_sizes=hidden)
    params = actor.init(jax.random.key(1), jnp.zeros((1, obs_dim)), jax.random.key(2), 0.0)
    meta = dict(obs_dim=obs_dim, action_dim=action_dim, hidden_sizes=list(hidden), env_name="toy")
    return actor, params, meta


def test_round_trip_acts_like_the_saved_actor(tmp_path):
    actor, params, meta = _actor_and_params()
    save_expert(tmp_path / "e", params, meta | {"eval_return": 12.5})
    expert = load_expert(tmp_path / "e", obs_dim=4, action_dim=2)
    obs = jax.random.normal(jax.random.key(3), (5, 4))
    want = deterministic_action(actor.apply(params, obs, jax.random.key(0), 0.0))
    got = expert.act(expert.params, obs, jax.random.key(7))
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), atol=1e-6)
    # Deterministic: the key does not matter.
    np.testing.assert_array_equal(
        np.asarray(got), np.asarray(expert.act(expert.params, obs, jax.random.key(8)))
    )
    assert expert.meta["eval_return"] == 12.5
    stochastic = load_expert(tmp_path / "e", obs_dim=4, action_dim=2, stochastic=True)
    a1 = stochastic.act(stochastic.params, obs, jax.random.key(7))
    assert not np.allclose(np.asarray(a1), np.asarray(got))


def test_missing_expert_says_how_to_get_one(tmp_path):
    with pytest.raises(FileNotFoundError, match="train_expert"):
        load_expert(tmp_path / "nowhere", obs_dim=4, action_dim=2)


def test_expert_for_another_env_is_refused(tmp_path):
    _, params, meta = _actor_and_params()
    save_expert(tmp_path / "e", params, meta)
    with pytest.raises(ValueError, match="obs_dim=4, action_dim=2"):
        load_expert(tmp_path / "e", obs_dim=17, action_dim=6)


def test_parameters_that_do_not_match_the_metadata_are_refused(tmp_path):
    _, params, meta = _actor_and_params(hidden=(8, 8))
    save_expert(tmp_path / "e", params, meta)
    meta_file = tmp_path / "e" / "expert.json"
    meta_file.write_text(json.dumps(meta | {"hidden_sizes": [16, 8]}))
    with pytest.raises(ValueError, match="does not match"):
        load_expert(tmp_path / "e", obs_dim=4, action_dim=2)


# ---------------------------------------------------------------- the expert of a task


def test_expert_of_another_task_is_refused_even_with_the_same_sizes(tmp_path):
    """Walker2d's and HalfCheetah's observations and actions have the same sizes (17, 6): only
    the recorded task tells their experts apart."""
    from arld_jax.expert import check_expert_task

    _, params, meta = _actor_and_params(obs_dim=17, action_dim=6)
    save_expert(tmp_path / "e", params, meta | {"env_name": "walker2d"})
    with pytest.raises(ValueError, match="acts in task 'walker2d', but this run's task is 'halfc"):
        load_expert(tmp_path / "e", obs_dim=17, action_dim=6, env_name="halfcheetah")
    assert load_expert(tmp_path / "e", 17, 6, env_name="walker2d").meta["env_name"] == "walker2d"
    with pytest.raises(ValueError, match="train_expert --preset sac_300k --env_name hopper"):
        check_expert_task({"env_name": "walker2d"}, tmp_path / "e", "hopper")


def test_an_expert_without_a_recorded_task_is_halfcheetahs_if_it_has_17_observations():
    from arld_jax.expert import check_expert_task, expert_task

    assert expert_task({"obs_dim": 17, "action_dim": 6}) == "halfcheetah"
    assert expert_task({"obs_dim": 4, "action_dim": 2}) is None  # unknown: sizes alone
    assert expert_task({"env_name": "walker2d", "obs_dim": 17}) == "walker2d"
    check_expert_task({"obs_dim": 17}, "old", "halfcheetah")
    check_expert_task({"obs_dim": 4}, "old", "hopper")  # unknown task: the sizes' check decides
    with pytest.raises(ValueError, match="acts in task 'halfcheetah'"):
        check_expert_task({"obs_dim": 17}, "old", "walker2d")


def test_the_default_expert_is_the_tasks_shipped_one(tmp_path, monkeypatch):
    """`--expert_path` unset: HalfCheetah's runs ask experiments/expert, the toy tasks their
    closed-form expert, and a task with nothing shipped is an error saying how to train one;
    once an expert is saved in the task's directory, it is the default."""
    from arld_jax import sweep
    from arld_jax.config import Config

    assert sweep.expert_path_for(Config()) == sweep.REPO_ROOT / "experiments" / "expert"
    assert sweep.expert_path_for(Config(env_name="toy")) is None
    given = Config(env_name="hopper", expert_path=str(tmp_path / "mine"))
    assert sweep.expert_path_for(given) == tmp_path / "mine"
    monkeypatch.setattr(sweep, "REPO_ROOT", tmp_path)  # a checkout with no hopper expert
    with pytest.raises(ValueError, match="no expert is shipped for task 'hopper'") as info:
        sweep.expert_path_for(Config(env_name="hopper"))
    # The command it names trains Hopper's expert: plain SAC, 5 seeds of 300k env steps.
    from arld_jax import run

    command = str(info.value).split("`")[1].split()
    assert command[:3] == ["python", "-m", "arld_jax.run"]
    args, how = run.parse_args(command[3:])
    assert args.command == "train_expert" and how.seeds == (0, 1, 2, 3, 4)
    assert (how.cfg.env_name, how.cfg.total_env_steps, how.cfg.strategy) == (
        "hopper",
        300_000,
        "none",
    )
    _, params, meta = _actor_and_params(obs_dim=11, action_dim=3)
    save_expert(tmp_path / "experiments" / "expert_hopper", params, meta | {"env_name": "hopper"})
    assert sweep.expert_path_for(Config(env_name="hopper")) == (
        tmp_path / "experiments" / "expert_hopper"
    )


def test_a_mismatched_expert_stops_a_sweep_before_anything_compiles(tmp_path, monkeypatch):
    """The shipped HalfCheetah expert asked by a Walker2d sweep, a task without a shipped expert,
    and an expert whose observation size differs: each a clear error, nothing written."""
    from arld_jax import driver, sweep
    from arld_jax.sweep import SHIPPED_EXPERT, Sweep, preset_tiny

    def querying(**fields):
        cfg = preset_tiny().cfg.replace(backend="mujoco", **fields)
        return Sweep(cfg=cfg, sweep={"strategy": ("none", "active")}, seeds=(0,))

    out = tmp_path / "out"
    with pytest.raises(SystemExit, match="acts in task 'halfcheetah'.*'walker2d'"):
        driver.run_sweep(querying(env_name="walker2d", expert_path=str(SHIPPED_EXPERT)), out)
    _, params, meta = _actor_and_params(obs_dim=4, action_dim=2)
    save_expert(tmp_path / "old", params, {k: v for k, v in meta.items() if k != "env_name"})
    with pytest.raises(SystemExit, match="obs_dim=4, action_dim=2.*task 'hopper' has obs_dim=11"):
        driver.run_sweep(querying(env_name="hopper", expert_path=str(tmp_path / "old")), out)
    monkeypatch.setattr(sweep, "REPO_ROOT", tmp_path)
    with pytest.raises(SystemExit, match="no expert is shipped for task 'ant'"):
        driver.run_sweep(querying(env_name="ant"), out)
    assert not out.exists()


@pytest.mark.parametrize("env_name", ["halfcheetah", "hopper", "walker2d", "ant"])
def test_each_shipped_expert_fits_its_task_and_acts_in_range(env_name):
    """The experts committed under experiments/ load as their task's default expert with its
    observation and action sizes, and act deterministically within the action bounds; their
    recorded check on fresh episodes is the one their README quotes (`evaluation.json`)."""
    from arld_jax.config import Config
    from arld_jax.envs import make_env
    from arld_jax.sweep import expert_path_for

    cfg = Config(env_name=env_name, backend="mujoco")
    path = expert_path_for(cfg)
    env = make_env(cfg)
    expert = load_expert(path, env.obs_dim, env.action_dim, env_name=env_name)
    obs = jax.random.normal(jax.random.key(0), (8, env.obs_dim))
    action = expert.act(expert.params, obs, jax.random.key(1))
    assert action.shape == (8, env.action_dim)
    assert bool(jnp.all(jnp.abs(action) <= 1.0))
    np.testing.assert_array_equal(action, expert.act(expert.params, obs, jax.random.key(2)))
    evaluation = json.loads((path / "evaluation.json").read_text())
    assert evaluation["episodes"] >= 10
    assert f"{evaluation['return_mean']:,.1f}" in (path / "README.md").read_text()
