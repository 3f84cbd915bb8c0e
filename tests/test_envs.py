"""The env wrapper of the trainer: `limit_batch` chunks a vmapped env step without changing it."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from arld_jax.config import Config
from arld_jax.envs import limit_batch, make_env


def _states_and_actions(env, runs: int, envs: int):
    keys = jax.random.split(jax.random.key(0), runs)
    states = jax.vmap(lambda k: env.reset(k, envs))(keys)
    actions = jax.random.uniform(
        jax.random.key(1), (runs, envs, env.action_dim), minval=-1.0, maxval=1.0
    )
    return states, actions


@pytest.mark.parametrize("max_batch", [1, 3, 4, 10, 64])
def test_limited_step_equals_plain_step_under_vmap(max_batch):
    """5 runs x 2 envs stepped in chunks of <= max_batch (with padding where 10 is not a multiple)
    give the same next states as one batch, also when the action is not vmapped."""
    plain = make_env(Config(env_name="toy", env_max_batch=-1))
    limited = make_env(Config(env_name="toy", env_max_batch=max_batch))
    states, actions = _states_and_actions(plain, 5, 2)
    for in_axes, acts in (((0, 0), actions), ((0, None), actions[0])):
        want = jax.jit(jax.vmap(plain.step, in_axes=in_axes))(states, acts)
        got = jax.jit(jax.vmap(limited.step, in_axes=in_axes))(states, acts)
        for w, g in zip(jax.tree.leaves(want), jax.tree.leaves(got), strict=True):
            assert g.shape == w.shape
            np.testing.assert_allclose(g, w, rtol=1e-6, atol=1e-6)


def test_limited_step_runs_in_chunks():
    """The vmapped program really steps chunks one after another: the step function sees a batch of
    at most max_batch envs (and exactly the plain step's batch without vmap)."""
    seen = []

    def step(state, action):
        seen.append(action.shape[0])
        return state

    limited = limit_batch(step, 4)
    states = jnp.zeros((5, 2, 3))
    actions = jnp.zeros((5, 2, 1))
    jax.make_jaxpr(jax.vmap(limited))(states, actions)
    # custom_vmap first traces the unbatched step (2 envs) for its output types, then the rule's
    # lax.map traces one chunk: 10 envs -> 3 chunks of 4 (2 padded).
    assert seen == [2, 4]
    seen.clear()
    jax.make_jaxpr(jax.vmap(limit_batch(step, 16)))(states, actions)
    assert seen == [2, 10]  # one chunk: the flattened batch is stepped directly
    seen.clear()
    jax.make_jaxpr(limited)(states[0], actions[0])
    assert seen == [2]


def test_building_halfcheetah_prints_no_third_party_noise():
    """Every run used to print MuJoCo-MJX's 'Failed to import warp', Brax's maintenance notice and
    MuJoCo's 'settotalmass' deprecation; a new process building the env prints none of them."""
    import subprocess
    import sys

    code = (
        "from arld_jax.config import Config; from arld_jax.envs import make_env; "
        "print('obs_dim', make_env(Config()).obs_dim)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "obs_dim 17"
    for noise in ("warp", "settotalmass", "not actively being maintained"):
        assert noise not in done.stdout + done.stderr, done.stdout + done.stderr
