"""Tests for arld_jax.config: validation, presets, derived values and HParams."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax.numpy as jnp
import numpy as np
import pytest

from arld_jax import config, query

# (field that must be named, overrides of the tiny preset). tiny(): num_envs 2, episode_length 50,
# total_env_steps 2000, learning_starts 200, eval_every 500, replay_capacity 2000,
# traces_per_eval 5.
INVALID: list[tuple[str, dict[str, Any]]] = [
    ("num_envs", dict(num_envs=0)),
    ("batch_size", dict(batch_size=4096)),  # > replay_capacity 2000
    ("backend", dict(backend="foo")),
    ("env_name", dict(env_name="foo")),
    ("strategy", dict(strategy="foo")),
    ("uncertainty", dict(uncertainty="foo")),
    ("t_query", dict(t_query=0.0)),
    ("t_query", dict(t_query=1.5)),
    ("budget", dict(budget=-1)),
    ("budget", dict(budget=2.5)),
    ("demo_steps", dict(demo_steps=0)),
    ("demo_steps", dict(demo_steps=1.5)),
    ("window_size", dict(window_size=0)),
    ("gamma", dict(gamma=1.0)),
    ("eval_every", dict(eval_every=501)),  # not a multiple of num_envs 2
    ("total_env_steps", dict(total_env_steps=2100)),  # not a multiple of eval_every 500
    ("updates_per_env_step", dict(num_envs=1, updates_per_env_step=0.3)),
    ("updates_per_env_step", dict(updates_per_env_step=0.0)),
    ("learning_starts", dict(learning_starts=2000)),  # == total_env_steps
    ("learning_starts", dict(learning_starts=5000)),
    ("learning_starts", dict(learning_starts=-1)),
    ("query_prob", dict(query_prob=1.5)),
    ("tau", dict(tau=0.0)),
    ("hidden_sizes", dict(hidden_sizes=())),
    ("window_records", dict(window_records="foo")),
    ("uncertainty_reduce", dict(uncertainty_reduce="foo")),
    ("log_std_min", dict(log_std_min=3.0)),  # >= log_std_max 2
    ("traces_per_eval", dict(traces_per_eval=7)),  # does not divide 250
    ("noisy_runs", dict(uncertainty="extrinsic", noisy_runs=False)),  # Noisy SAC needs the noise
]


@pytest.mark.parametrize(
    ("field", "overrides"), INVALID, ids=[f"{f}={list(o.values())[-1]!r}" for f, o in INVALID]
)
def test_invalid_value_raises_naming_the_field(field: str, overrides: dict[str, Any]) -> None:
    value = overrides[field] if field in overrides else None
    with pytest.raises(ValueError, match=rf"^Config\.{field} = ") as err:
        config.tiny(**overrides)
    if value is not None:
        assert repr(value) in str(err.value)  # the message shows the offending value
    assert "allowed" in str(err.value)


def test_bad_backend_names_the_field_and_every_allowed_value() -> None:
    with pytest.raises(ValueError) as err:
        config.Config(backend="gpu")
    assert str(err.value) == (
        "Config.backend = 'gpu' is invalid: allowed one of 'auto', 'mjx', 'mujoco', "
        "'generalized', 'positional', 'spring'."
    )


@pytest.mark.parametrize(
    ("platform", "physics"), [("cpu", "mujoco"), ("gpu", "mjx"), ("tpu", "mjx")]
)
def test_auto_backend_is_resolved_when_the_config_is_built(monkeypatch, platform, physics) -> None:
    """'auto' becomes the machine's fastest physics at construction (the C engine when jax computes
    on the CPU, MJX on an accelerator), so config.json records what ran; explicit choices stay."""
    monkeypatch.setattr(config, "jax_platform", lambda: platform)
    assert config.auto_backend(platform) == physics
    cfg = config.Config()
    assert cfg.backend == physics and config.Config(backend="auto").backend == physics
    assert dataclasses.asdict(cfg)["backend"] == physics
    assert cfg.replace(budget=7).backend == physics
    for chosen in ("mjx", "mujoco"):
        assert config.Config(backend=chosen).backend == chosen
        assert cfg.replace(backend=chosen).backend == chosen
    line = config.physics_line(cfg, platform)
    assert line.startswith(f"physics: {physics} (") and f"--backend auto on {platform}" in line
    other = "mjx" if physics == "mujoco" else "mujoco"
    line = config.physics_line(cfg.replace(backend=other), platform)
    assert f"auto would take {physics} on {platform}" in line
    assert "does not apply" in config.physics_line(config.tiny(), platform)
    solver = cfg.replace(env_name="ant", solver_iterations=100, solver_ls_iterations=50)
    assert config.solver_options(solver) == {"iterations": 100, "ls_iterations": 50}
    assert config.physics_line(solver, platform).endswith(
        ", 100 solver iterations, 50 line searches)"
    )
    assert config.solver_options(cfg) == {} and "solver" not in config.physics_line(cfg, platform)
    assert config.physics_line(cfg.replace(env_name="ant", contacts="all"), platform).endswith(
        ", every body geom touches the floor)"
    )
    rk4 = solver.replace(integrator="rk4")
    assert config.model_options(rk4) == {"iterations": 100, "ls_iterations": 50, "integrator": 1}
    assert config.model_options(cfg) == {} and "Runge" not in config.physics_line(cfg, platform)
    assert config.physics_line(rk4, platform).endswith(", 4th-order Runge-Kutta)")


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        (dict(solver_iterations=-1), "solver_iterations = -1 is invalid: allowed an integer >= 1"),
        (dict(solver_ls_iterations=2.5), "solver_ls_iterations = 2.5 is invalid"),
        (dict(solver_iterations=True), "solver_iterations = True is invalid"),
        (
            dict(env_name="toy", solver_iterations=10),
            "allowed 0 with env_name 'toy' and backend 'mujoco' \\(MuJoCo's model options apply",
        ),
        (dict(backend="spring", solver_ls_iterations=10), "backend 'spring'"),
        (dict(contacts="floor"), "contacts = 'floor' is invalid: allowed one of 'task', 'all'"),
        (
            dict(env_name="toy", contacts="all"),
            "allowed 'task' with env_name 'toy' and backend 'mujoco' \\(MuJoCo's model options",
        ),
        (dict(backend="spring", contacts="all"), "contacts = 'all' is invalid.*backend 'spring'"),
        (dict(integrator="rk2"), "integrator = 'rk2' is invalid: allowed one of 'task', 'rk4'"),
        (
            dict(env_name="toy", integrator="rk4"),
            "integrator = 'rk4' is invalid: allowed 'task' with env_name 'toy'",
        ),
    ],
)
def test_solver_options_are_checked(changes, message) -> None:
    """A solver option is a whole number >= 0, and nonzero only where MuJoCo's solver runs; the
    contacts are a named choice, other than the task's own only where MuJoCo runs."""
    base = dict(env_name="ant", backend="mujoco")
    with pytest.raises(ValueError, match=message):
        config.Config(**{**base, **changes})


def test_warmup_periods_count_every_period_with_a_random_step() -> None:
    # tiny: warm-up 100 iterations, 250 per period -> period 0 is partly warm-up.
    assert config.tiny().warmup_periods == 1
    # 5,000 warm-up steps, an evaluation every 2,000: periods 0, 1 and half of 2.
    assert config.Config(learning_starts=5_000, eval_every=2_000).warmup_periods == 3
    assert config.Config(learning_starts=4_000, eval_every=2_000).warmup_periods == 2
    assert config.tiny(learning_starts=0).warmup_periods == 0


def test_cell_names_are_the_papers_with_the_swept_values_each_strategy_uses() -> None:
    swept = ["strategy", "uncertainty", "demo_steps"]
    base = {"uncertainty": "intrinsic", "query_prob": 0.2, "t_query": 0.1, "demo_steps": 5}
    name = lambda agent="sac", **v: config.cell_name(base | v, swept, agent)  # noqa: E731
    assert name(strategy="none") == "SAC"  # C does not change a run that never asks
    assert name(strategy="greedy", agent="boot_td3") == "GQBootTD3 C=5"
    assert name(strategy="bernoulli", uncertainty="extrinsic") == "BQNoisySAC b=0.2 C=5"
    assert name(strategy="active", agent="td3") == "AQTD3 t_query=0.1 C=5"
    values = base | {"strategy": "active"}
    assert config.cell_name(values, swept, exclude=("t_query",)) == "AQSAC C=5"


def test_replace_validates_again() -> None:
    cfg = config.tiny()
    with pytest.raises(ValueError, match=r"Config\.budget"):
        cfg.replace(budget=-1)
    assert cfg.replace(budget=7).budget == 7


def test_config_is_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.tiny().budget = 3  # type: ignore[misc]


def test_presets_construct_with_their_documented_values() -> None:
    assert set(config.PRESETS) == {"tiny", "halfcheetah", "paper"}
    tiny = config.PRESETS["tiny"]()
    assert (tiny.env_name, tiny.num_envs, tiny.hidden_sizes) == ("toy", 2, (32, 32))
    cheetah = config.PRESETS["halfcheetah"]()
    assert (cheetah.env_name, cheetah.backend, cheetah.total_env_steps) == (
        "halfcheetah",
        "mjx",
        100_000,
    )
    assert cheetah.replay_capacity == 100_000
    paper = config.PRESETS["paper"]()
    # Appendix A.1: 400k steps, budget 10k, N_r 5000, eval every 5000, 256x256 networks, alpha 0.2.
    assert paper.total_env_steps == 400_000 and paper.budget == 10_000
    assert paper.window_size == 5_000 and paper.eval_every == 5_000 and paper.num_envs == 1
    assert paper.hidden_sizes == (256, 256) and paper.init_alpha == 0.2
    assert not paper.autotune_alpha
    # Overrides go through validation too.
    assert config.paper(budget=5).budget == 5
    with pytest.raises(ValueError, match=r"Config\.num_envs"):
        config.paper(num_envs=0)


@pytest.mark.parametrize(
    ("cfg", "expected"),
    [
        # tiny: 2000 / 2 iterations, 500 / 2 per eval, 2000 / 500 evals, ceil(200 / 2), 1.0 * 2
        (config.tiny(), (1000, 250, 4, 100, 2)),
        # 4 envs: 2000 / 4, 500 / 4, 4, ceil(202 / 4) = ceil(50.5) = 51, 0.5 * 4
        (
            config.tiny(num_envs=4, learning_starts=202, updates_per_env_step=0.5),
            (500, 125, 4, 51, 2),
        ),
        # paper: 400000 / 1, 5000 / 1, 80, 5000 / 1, 1
        (config.paper(), (400_000, 5_000, 80, 5_000, 1)),
        # 3 envs, 1/3 update per env step -> one update per iteration; ceil(100 / 3) = 34
        (
            config.tiny(
                num_envs=3,
                eval_every=300,
                total_env_steps=1800,
                learning_starts=100,
                traces_per_eval=5,
                updates_per_env_step=1 / 3,
            ),
            (600, 100, 6, 34, 1),
        ),
    ],
)
def test_derived_values(cfg: config.Config, expected: tuple[int, ...]) -> None:
    got = (
        cfg.num_iterations,
        cfg.iters_per_eval,
        cfg.num_evals,
        cfg.warmup_iters,
        cfg.updates_per_iter,
    )
    assert got == expected


@pytest.mark.parametrize("strategy", config.STRATEGIES)
@pytest.mark.parametrize("uncertainty", config.UNCERTAINTIES)
def test_hparams_from_config_maps_names_to_ids(strategy: str, uncertainty: str) -> None:
    hp = config.hparams_from_config(config.tiny(strategy=strategy, uncertainty=uncertainty))
    expected_id = {"none": 0, "greedy": 1, "bernoulli": 2, "active": 3}[strategy]
    assert hp.strategy.dtype == jnp.int32 and int(hp.strategy) == expected_id
    # query.py decides with the same ids.
    assert (
        expected_id
        == {
            "none": query.NONE,
            "greedy": query.GREEDY,
            "bernoulli": query.BERNOULLI,
            "active": query.ACTIVE,
        }[strategy]
    )
    assert float(hp.noisy) == (1.0 if uncertainty == "extrinsic" else 0.0)


def test_hparams_carry_the_sweepable_values() -> None:
    cfg = config.tiny(
        query_prob=0.25,
        t_query=0.3,
        demo_steps=5,
        budget=77,
        eps_demo=0.5,
        actor_lr=1e-3,
        critic_lr=2e-3,
        alpha_lr=3e-3,
        gamma=0.9,
        tau=0.02,
        reward_scale=5.0,
        init_alpha=0.1,
    )
    hp = config.hparams_from_config(cfg)
    for name in (
        "query_prob",
        "t_query",
        "eps_demo",
        "actor_lr",
        "critic_lr",
        "alpha_lr",
        "gamma",
        "tau",
        "reward_scale",
        "init_alpha",
    ):
        value = getattr(hp, name)
        assert value.dtype == jnp.float32 and value.shape == (), name
        np.testing.assert_allclose(value, getattr(cfg, name), rtol=1e-6, err_msg=name)
    for name in ("demo_steps", "budget"):
        assert getattr(hp, name).dtype == jnp.int32 and int(getattr(hp, name)) == getattr(cfg, name)
    # Every sweepable field travels in HParams (seed as a key, uncertainty as `noisy`).
    hp_fields = {f.name for f in dataclasses.fields(config.HParams)}
    assert set(config.SWEEPABLE) - {"seed", "uncertainty"} <= hp_fields
