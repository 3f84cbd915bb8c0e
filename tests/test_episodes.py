"""Episodes that end: termination vs truncation in the target, envs that end and restart alone, a
demonstration cut by its episode's end, and evaluation on a task that terminates (`toy_fall`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.experimental import io_callback

from arld_jax import losses, query
from arld_jax.config import hparams_from_config, tiny
from arld_jax.envs import TOY_FALL_ERROR, make_env, toy_target_action
from arld_jax.evaluate import rollout
from arld_jax.expert import Expert
from arld_jax.tasks.toy import _TOY_W
from arld_jax.train import episode_ends, make_train

LENGTH = 12  # a short time limit, so the run holds both kinds of episode end
NUM_ENVS = 2
C = 4


def test_episode_ends_tells_termination_from_truncation() -> None:
    """Hand cases: a fall ends the episode at any step; the time limit ends it after `length`
    steps (episode_step counts the steps before this one); a fall at the limit is a termination."""
    terminated = jnp.array([0.0, 1.0, 0.0, 1.0, 0.0])
    episode_step = jnp.array([3, 3, LENGTH - 1, LENGTH - 1, LENGTH - 2])
    done, truncated = episode_ends(terminated, episode_step, LENGTH)
    np.testing.assert_array_equal(done, [False, True, True, True, False])
    np.testing.assert_array_equal(truncated, [False, False, True, False, False])


def test_soft_target_bootstraps_through_truncation_not_termination() -> None:
    """The SAC target of the two kinds of end, by hand: r = 0.5, reward scale 2, gamma 0.9,
    Q'(s', a') = [4, 3], log pi' = -1, alpha 0.2: soft value = 3 + 0.2 = 3.2.
    Truncated (terminated = 0): y = 2 * 0.5 + 0.9 * 3.2 = 3.88. Terminated: y = 1.0."""
    for terminated, expected in ((0.0, 3.88), (1.0, 1.0)):
        y = losses.soft_q_target(0.5, terminated, jnp.array([4.0, 3.0]), -1.0, 0.2, 0.9, 2.0)
        assert float(y) == pytest.approx(expected, abs=1e-6)


def test_a_demonstration_run_ends_with_its_episode() -> None:
    """Two envs start C = 4 runs (budget 10) and take one demonstrated step each; then env 0's
    episode ends: its run is cancelled, its step stays spent and its 3 reserved steps return to the
    budget (free = 10 - 2 spent - 3 still reserved by env 1 = 5)."""
    hp = hparams_from_config(tiny(strategy="greedy", demo_steps=4, budget=10))
    qs = query.init_query_state(2, 8)
    u = jnp.zeros(2)
    qs, is_demo, new = query.query_step(qs, jax.random.key(0), u, jnp.array([50, 50]), hp)
    assert bool(is_demo[0]) and int(qs.demo_remaining[0]) == 3 and int(qs.demos_used) == 2
    qs = query.end_episodes(qs, jnp.array([True, False]))
    np.testing.assert_array_equal(qs.demo_remaining, [0, 3])
    assert int(qs.demos_used) == 2  # what was executed stays spent
    free = hp.budget - qs.demos_used - jnp.sum(qs.demo_remaining)
    assert int(free) == 10 - 2 - 3


def _clumsy_expert(seen: list) -> Expert:
    """An expert that acts against the toy target half the time it is asked: it falls often, so
    demonstration runs meet terminations. Its `observe` hook (a person's page uses it) appends
    what every iteration shows it to `seen`: (env_step, obs, next_obs, fell)."""

    def act(p, obs, key, context=None):  # noqa: ANN001, ANN202
        sign = jnp.where(jax.random.uniform(key, obs.shape[:1]) < 0.5, -1.0, 1.0)
        return sign[:, None] * toy_target_action(obs)

    def observe(obs, next_obs, fell, context):  # noqa: ANN001, ANN202
        def host(*args):  # noqa: ANN002, ANN202
            seen.append(tuple(np.asarray(a) for a in args))
            return np.int32(0)

        shape = jax.ShapeDtypeStruct((), jnp.int32)
        return io_callback(host, shape, context.env_step, obs, next_obs, fell, ordered=True)

    return Expert(params={}, act=act, meta={"name": "clumsy"}, observe=observe)


@pytest.fixture(scope="module")
def falling_run():
    """One run of `toy_fall` (2 envs, 12-step time limit), Bernoulli queries with C = 4 to a clumsy
    expert, every transition kept in the replay in the order it was added (capacity = the run)."""
    cfg = tiny(
        env_name="toy_fall",
        num_envs=NUM_ENVS,
        episode_length=LENGTH,
        total_env_steps=600,
        eval_every=300,
        learning_starts=100,
        replay_capacity=600,
        strategy="bernoulli",
        query_prob=0.1,
        demo_steps=C,
        budget=10_000,
    )
    seen: list = []
    trainer = make_train(cfg, _clumsy_expert(seen))
    state, metrics = jax.jit(trainer.train)(jax.random.key(3), hparams_from_config(cfg))
    data = jax.tree.map(np.asarray, state.replay.data)
    per_env = jax.tree.map(lambda x: x.reshape(-1, NUM_ENVS, *x.shape[1:]), data)  # [T, E, ...]
    return cfg, state, jax.tree.map(np.asarray, metrics), per_env, seen


def _episodes(per_env, e: int) -> list[tuple[int, int]]:
    """[start, end] rows (inclusive) of env e's episodes, read from the replay: an episode ends at a
    stored termination or after LENGTH steps."""
    spans, start = [], 0
    for t in range(per_env.obs.shape[0]):
        if per_env.terminated[t, e] > 0 or t - start + 1 == LENGTH:
            spans.append((start, t))
            start = t + 1
    return spans


def test_envs_end_and_restart_alone(falling_run) -> None:
    """Within an episode the next stored obs is the true next state; after an end (a fall or the
    time limit) the env restarts from a fresh initial state (in [-1, 1]^4, not the stored next
    obs); each fall is stored with terminated = 1 and its reward shows the fall rule; a time-limit
    end has terminated = 0; and the two envs end at different steps."""
    _, _, metrics, d, _ = falling_run
    ends = {e: [end for _, end in _episodes(d, e)] for e in range(NUM_ENVS)}
    falls = truncations = 0
    for e in range(NUM_ENVS):
        for t in range(d.obs.shape[0] - 1):
            if t in ends[e]:
                assert not np.allclose(d.obs[t + 1, e], d.next_obs[t, e])
                assert np.all(np.abs(d.obs[t + 1, e]) <= 1.0)  # the reset distribution
            else:
                np.testing.assert_array_equal(d.obs[t + 1, e], d.next_obs[t, e])
            if d.terminated[t, e] > 0:
                falls += 1
                assert d.reward[t, e] < 1.0 - TOY_FALL_ERROR + 1e-6
            else:
                assert d.reward[t, e] >= 1.0 - TOY_FALL_ERROR - 1e-6
                truncations += t in ends[e]
    assert falls > 10 and truncations > 3, (falls, truncations)
    assert ends[0] != ends[1]
    # The metrics count the same episodes: ends in the replay = episodes of the periods.
    assert int(metrics.episodes.sum()) == sum(len(v) for v in ends.values())
    assert 0.0 < float(np.nanmean(metrics.fell)) < 1.0


def test_a_demonstration_is_cut_by_a_fall(falling_run) -> None:
    """Demo runs never outlive their episode: a run of consecutive demonstrated steps within an
    episode is at most C long unless a new query followed at once, and the first step after a fall
    is the start of a new run (is_demo there is a fresh Bernoulli query, rare at b = 0.1), never the
    rest of the cut one. Every demonstrated step is counted in the budget, and nothing else."""
    _, state, _, d, _ = falling_run
    cut = continued = 0
    for e in range(NUM_ENVS):
        for start, end in _episodes(d, e):
            demo = d.is_demo[start : end + 1, e] > 0
            run = 0
            for k, flag in enumerate(demo):
                run = run + 1 if flag else 0
                if flag and k == len(demo) - 1 and d.terminated[end, e] > 0 and run < C:
                    cut += 1  # the episode fell inside a demonstration run
            if end + 1 < d.obs.shape[0] and demo[-1] and d.terminated[end, e] > 0:
                continued += int(d.is_demo[end + 1, e] > 0)
    assert cut >= 3, cut
    assert continued <= cut // 3, (continued, cut)
    assert int(state.query.demos_used) == int(d.is_demo.sum())


def test_the_expert_sees_every_step_and_every_fall(falling_run) -> None:
    """The expert's `observe` hook (how a person's page sees the run) is called once per iteration,
    in order, after the env step: with the states acted in, the true next states (the fallen
    state at a fall, not the fresh one that replaces it) and the falls, exactly as the replay
    stores them."""
    _, _, _, d, seen = falling_run
    steps, obs, next_obs, fell = (np.stack(x) for x in zip(*seen, strict=True))
    np.testing.assert_array_equal(steps, NUM_ENVS * np.arange(d.obs.shape[0]))
    np.testing.assert_array_equal(obs, d.obs)
    np.testing.assert_array_equal(next_obs, d.next_obs)
    np.testing.assert_array_equal(fell, d.terminated > 0)
    assert fell.sum() > 10


def test_evaluation_on_a_task_that_terminates() -> None:
    """Deterministic episodes of constructed policies on toy_fall, against a numpy rollout of the
    same dynamics: the target policy never falls (return = length); acting a fixed (1, -1) falls,
    and the return counts the terminal step's reward and nothing after it."""
    env = make_env(tiny(env_name="toy_fall"))
    n, length = 6, 40
    key = jax.random.key(11)
    s0 = np.asarray(env.reset(key, n).obs, np.float64)

    target = rollout(env, toy_target_action, key, n, length)
    np.testing.assert_allclose(target.episode_return, length, rtol=1e-5)
    np.testing.assert_array_equal(target.fell, 0.0)
    np.testing.assert_array_equal(target.length, length)

    fixed = np.array([1.0, -1.0])
    ev = rollout(
        env, lambda obs: jnp.broadcast_to(jnp.asarray(fixed), obs.shape[:1] + (2,)), key, n, length
    )
    for i in range(n):  # the toy dynamics in numpy (envs._toy_env)
        s, ret, steps, fell = s0[i], 0.0, 0, False
        for _ in range(length):
            err = np.mean((fixed - np.tanh(2.0 * s @ _TOY_W.astype(np.float64))) ** 2)
            ret, steps = ret + 1.0 - err, steps + 1
            s = np.clip(0.9 * s + 0.3 * np.concatenate([fixed, -fixed]), -2.0, 2.0)
            if err > TOY_FALL_ERROR:
                fell = True
                break
        assert float(ev.episode_return[i]) == pytest.approx(ret, abs=1e-3)
        assert float(ev.length[i]) == steps and float(ev.fell[i]) == float(fell)
    assert float(ev.fell.mean()) > 0  # the constructed policy does fall
