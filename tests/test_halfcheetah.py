"""The real env inside the scanned loop, with each physics backend: MuJoCo-MJX (a few minutes of
compiling on CPU) and MuJoCo's C engine through a host callback (seconds).

Checks what only the physics can show: every episode starts from a fresh random initial state (not
Brax's AutoResetWrapper's frozen first state), the true next observation is stored at the time
limit with terminated = 0 (bootstrap through truncation), MJX's rewards are Brax's formula worked
out from the bodies' positions, and the training return is the sum of the stored rewards. The
upside-down fraction of an evaluation is checked on constructed states (no physics).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from arld_jax.config import Config, hparams_from_config
from arld_jax.envs import Env, EnvState, halfcheetah_upside_down
from arld_jax.evaluate import evaluate_policy
from arld_jax.train import make_train

slow = pytest.mark.slow  # compiles MuJoCo-MJX, or the training loop with each physics


@pytest.fixture(scope="module", params=["mjx", "mujoco"])
def cheetah_run(request):
    cfg = Config(
        backend=request.param,
        num_envs=2,
        episode_length=40,
        total_env_steps=240,
        learning_starts=80,
        eval_every=120,
        num_eval_episodes=2,
        hidden_sizes=(32, 32),
        batch_size=32,
        replay_capacity=240,
        window_size=40,
        traces_per_eval=6,
        state_sample_size=16,
    )
    trainer = make_train(cfg)
    state, metrics = jax.jit(trainer.train)(jax.random.key(0), hparams_from_config(cfg))
    return cfg, state, metrics


@slow
def test_dimensions_and_the_training_return_is_the_stored_rewards(cheetah_run):
    cfg, state, metrics = cheetah_run
    data = state.replay.data
    assert data.obs.shape == (cfg.replay_capacity, 17)
    assert data.action.shape == (cfg.replay_capacity, 6)
    assert int(state.replay.size) == cfg.total_env_steps
    for name in ("eval_return", "critic_loss", "actor_loss", "sigma"):
        assert np.all(np.isfinite(np.asarray(getattr(metrics, name)))), name
    # 120 iterations of 2 envs: episodes of 40 end at iterations 39 (period 0: iterations 0-59),
    # 79 and 119 (period 1). An episode's return is its env-mean sum of the stored (unscaled)
    # rewards; a period's training return is the mean over the episodes that ended in it.
    reward = np.asarray(data.reward, np.float64).reshape(cfg.num_iterations, cfg.num_envs)
    episodes = reward.reshape(-1, cfg.episode_length, cfg.num_envs).sum(axis=1).mean(axis=1)
    np.testing.assert_allclose(
        np.asarray(metrics.train_return), [episodes[0], episodes[1:].mean()], rtol=1e-5
    )


@slow
def test_fresh_initial_state_every_episode_and_true_next_obs(cheetah_run):
    cfg, state, metrics = cheetah_run
    data = state.replay.data
    obs = np.asarray(data.obs).reshape(cfg.num_iterations, cfg.num_envs, -1)
    next_obs = np.asarray(data.next_obs).reshape(cfg.num_iterations, cfg.num_envs, -1)
    starts = obs[:: cfg.episode_length]  # [episodes, envs, 17]
    flat = starts.reshape(-1, starts.shape[-1])
    # All episode starts differ from each other (fresh random initial states)...
    dists = np.linalg.norm(flat[:, None] - flat[None], axis=-1)
    assert np.all(dists[~np.eye(len(flat), dtype=bool)] > 1e-4)
    # ...and are near HalfCheetah's initial pose (reset noise 0.1), unlike mid-episode states.
    assert np.abs(flat).max() < 0.5
    # Within an episode, obs[t+1] == next_obs[t]; at the time limit next_obs is the true next
    # observation (not the reset one) and terminated stays 0 so the critic bootstraps through it.
    ends = np.arange(cfg.episode_length - 1, cfg.num_iterations, cfg.episode_length)
    inner = np.setdiff1d(np.arange(cfg.num_iterations - 1), ends)
    np.testing.assert_allclose(next_obs[inner], obs[inner + 1], atol=1e-5)
    assert not np.allclose(next_obs[ends[:-1]], obs[ends[:-1] + 1], atol=1e-3)
    assert float(np.asarray(data.terminated).max()) == 0.0


@slow
def test_gait_metric_matches_the_visited_states(cheetah_run):
    """The per-period upside-down fraction is the mean of `gait.upside_down` over the states the
    run visited in that period (checked against the replay, which holds every visited state here),
    and the fresh cheetah of every episode start is upright."""
    from arld_jax import gait

    cfg, state, metrics = cheetah_run
    obs = np.asarray(state.replay.data.obs).reshape(cfg.num_evals, -1, 17)
    expected = np.mean(gait.upside_down(obs), axis=1)
    np.testing.assert_allclose(np.asarray(metrics.upside_down), expected, atol=1e-6)
    starts = obs.reshape(cfg.num_iterations, cfg.num_envs, 17)[:: cfg.episode_length]
    assert not np.any(gait.upside_down(starts))


def _pitched_env(pitch0: float, rate: float) -> Env:
    """A stand-in with HalfCheetah's observation whose root pitch (obs[..., 1]) is
    pitch0 + rate * t at step t; every other entry 0, rewards 0."""

    def obs_at(t: jax.Array) -> jax.Array:
        return jnp.zeros((*t.shape, 17)).at[..., 1].set(pitch0 + rate * t)

    def reset(key, n):  # noqa: ANN001, ANN202
        t = jnp.zeros(n)
        return EnvState(inner=t, obs=obs_at(t), reward=jnp.zeros(n), terminated=jnp.zeros(n))

    def step(state, action):  # noqa: ANN001, ANN202
        t = state.inner + 1
        return EnvState(
            inner=t, obs=obs_at(t), reward=jnp.zeros_like(t), terminated=jnp.zeros_like(t)
        )

    return Env(
        reset=reset, step=step, obs_dim=17, action_dim=6, upside_down=halfcheetah_upside_down
    )


@pytest.mark.parametrize(
    "pitch0, rate, flipped",
    [
        (0.0, 0.0, 0.0),  # upright throughout
        (np.pi, 0.0, 1.0),  # on its back throughout
        (2 * np.pi, 0.0, 0.0),  # a full turn: upright again
        # pitches 0.0, 0.1, ..., 3.9 of the 40 evaluated states: |pitch| > pi/2 from t = 16 on
        (0.0, 0.1, 24 / 40),
    ],
)
def test_evaluation_counts_the_upside_down_states(pitch0: float, rate: float, flipped: float):
    """The evaluation's upside-down fraction (PeriodMetrics.eval_upside_down) is the share of the
    states it visits with the torso upside down, each state counted before its step."""
    policy = lambda obs: jnp.zeros((obs.shape[0], 6))  # noqa: E731
    env = _pitched_env(pitch0, rate)
    fraction = evaluate_policy(env, policy, jax.random.key(0), 2, 40).upside_down
    assert float(fraction) == pytest.approx(flipped, abs=1e-6)
