"""The env wrappers of the trainer: `limit_batch` chunks a vmapped env step without changing it;
the 'mujoco' backend is Brax's halfcheetah stepped by MuJoCo's C engine."""

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


def test_third_party_noise_is_dropped_and_everything_else_kept(capfd):
    """The filter works at the file-descriptor level (MuJoCo's C code writes there): known
    third-party notices are dropped, other lines come through, and after an error everything is
    re-printed so nothing that explains it is lost."""
    import os

    from arld_jax.envs import without_third_party_noise

    with without_third_party_noise():
        os.write(1, b"Failed to import warp: No module named 'warp'\n")
        os.write(2, b"WARNING: compiler attribute 'settotalmass' is deprecated\n")
        os.write(1, b"a message of our own\n")
    out, err = capfd.readouterr()
    assert "warp" not in out + err and "settotalmass" not in out + err
    assert "a message of our own" in out + err
    with pytest.raises(RuntimeError), without_third_party_noise():
        os.write(1, b"Failed to import warp: it matters now\n")
        raise RuntimeError("boom")
    out, err = capfd.readouterr()
    assert "it matters now" in out + err


def test_building_halfcheetah_prints_no_third_party_noise(capfd):
    """Building Brax's halfcheetah printed MuJoCo's 'settotalmass' deprecation and Brax's
    maintenance notice at every run; now neither (the MJX import's Warp message is covered by the
    filter test above: it is printed once per process, at the first import)."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = make_env(Config(backend="mjx"))
    out, err = capfd.readouterr()
    assert env.obs_dim == 17
    assert "settotalmass" not in out + err, out + err
    assert not [w for w in caught if "not actively being maintained" in str(w.message)]


# ---------------------------------------------------------------- MuJoCo's C engine ('mujoco')


@pytest.fixture(scope="module")
def c_env():
    return make_env(Config(backend="mujoco"))


def test_mujoco_backend_is_brax_halfcheetah_in_c():
    """Same key: bit-identical initial states to the 'mjx' backend; the same actions for 10 steps:
    the same observations and rewards to within float32 drift (the two engines differ only in
    their arithmetic, float64 in C against float32 in MJX; over tens more steps the chaotic
    trajectories part). MJX's reward is also worked out from its states: Brax's halfcheetah
    (brax/envs/half_cheetah.py), r = 1.0 (x' - x) / dt - 0.1 sum(a^2), x the torso's x position
    before and after the step, dt = 5 frames x the model's 0.01 s = 0.05 s. Compiles one MJX step
    (about a minute on CPU)."""
    from brax import envs as brax_envs

    c, mjx = make_env(Config(backend="mujoco")), make_env(Config(backend="mjx"))
    assert (c.obs_dim, c.action_dim) == (mjx.obs_dim, mjx.action_dim) == (17, 6)
    torso = brax_envs.get_environment("halfcheetah", backend="mjx").sys.mj_model.body("torso").id
    key = jax.random.key(3)
    sc = jax.jit(c.reset, static_argnums=1)(key, 2)
    sm = jax.jit(mjx.reset, static_argnums=1)(key, 2)
    np.testing.assert_array_equal(sc.obs, sm.obs)
    step_c, step_m = jax.jit(c.step), jax.jit(mjx.step)
    actions = jax.random.uniform(jax.random.key(4), (10, 2, 6), minval=-1.0, maxval=1.0)
    velocities = []
    for t in range(10):
        before = sm
        sc, sm = step_c(sc, actions[t]), step_m(sm, actions[t])
        np.testing.assert_allclose(sc.obs, sm.obs, atol=2e-3, err_msg=f"step {t}")
        np.testing.assert_allclose(sc.reward, sm.reward, atol=2e-3, err_msg=f"step {t}")
        x0, x1 = (np.asarray(s.inner.pipeline_state.xpos[:, torso, 0]) for s in (before, sm))
        velocity = (x1 - x0) / 0.05
        ctrl_cost = np.sum(np.square(np.asarray(actions[t])), axis=-1)
        np.testing.assert_allclose(
            sm.reward, velocity - 0.1 * ctrl_cost, rtol=1e-4, atol=1e-4, err_msg=f"step {t}"
        )
        velocities.append(velocity)
    assert np.max(np.abs(velocities)) > 0.1  # the torso moved: the velocity term was tested
    assert float(jnp.max(jnp.abs(sc.obs - sm.obs))) > 0  # two engines, not one
    assert float(jnp.max(jnp.abs(sc.obs - c.reset(key, 2).obs))) > 0.1  # it moved


def test_mujoco_step_is_a_pure_function_of_its_state(c_env):
    """The host step depends on its arguments only (the scratch MjData carries nothing between
    calls): a state stepped again gives the same next state bit for bit, after other states were
    stepped in between; vmapped over runs equals run by run; and programs dispatched back to back
    (their callbacks may run on different threads at once) give the same result."""
    states, actions = _states_and_actions(c_env, 3, 2)
    step = jax.jit(jax.vmap(c_env.step))
    first = step(states, actions)
    for _ in range(3):  # other states through the same scratch data
        step(first, actions)
    again = step(states, actions)
    for a, b in zip(jax.tree.leaves(first), jax.tree.leaves(again), strict=True):
        np.testing.assert_array_equal(a, b)
    one = jax.jit(c_env.step)
    for r in range(3):
        run_r = one(jax.tree.map(lambda x: x[r], states), actions[r])  # noqa: B023
        np.testing.assert_array_equal(run_r.obs, first.obs[r])
    pending = [step(states, actions) for _ in range(4)]  # not blocked on: overlapping callbacks
    for out in pending:
        np.testing.assert_array_equal(out.obs, first.obs)
    assert not np.array_equal(first.obs, states.obs)


def test_mujoco_reward_is_forward_velocity_minus_control_cost(c_env):
    """r = (x' - x) / dt - 0.1 |a|^2 with x the torso's x: the reward of a step equals the change
    in the carried x over Brax's dt (0.05 s) minus the control cost."""
    state = c_env.reset(jax.random.key(5), 4)
    action = jnp.linspace(-1.0, 1.0, 24).reshape(4, 6)
    nxt = jax.jit(c_env.step)(state, action)
    velocity = (nxt.inner.x - state.inner.x) / 0.05
    expected = velocity - 0.1 * jnp.sum(action**2, axis=-1)
    np.testing.assert_allclose(nxt.reward, expected, rtol=1e-4, atol=1e-4)
    assert np.all(np.asarray(nxt.terminated) == 0)
