"""The tasks and their physics: every Brax task gives the same observation, reward and termination on
both backends (MJX, and MuJoCo's C engine behind a host callback) for the same state and action;
`limit_batch` chunks a vmapped env step without changing it; the C step is a pure function.

Each MJX check compiles one MJX step of the task (tens of seconds to minutes on CPU; the other
checks compile no MJX at all). MJX's state is not made by its own reset (a second compile): the C
engine's state is written into a zero MJX state of the right shapes, which is enough because MJX's
step recomputes everything else from qpos, qvel and the warm start before it integrates.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from arld_jax.config import CONTACTS, ENVS, Config
from arld_jax.envs import limit_batch, make_env
from arld_jax.physics import load_brax_env
from arld_jax.tasks import BRAX_TASKS, REGISTRY

slow = pytest.mark.slow  # compiles MuJoCo-MJX

UNHEALTHY: dict[str, tuple[int, float]] = {
    "hopper": (2, 0.5),  # pitched forward past 0.2 rad
    "walker2d": (2, 1.5),  # pitched past 1 rad
    "ant": (2, 1.5),  # torso above 1.0 (in the air)
    "ant_contact": (2, 1.5),  # Ant's body and health rule
    "humanoid": (2, 2.5),  # torso above 2.0 (in the air)
    "halfcheetah": (2, np.pi),  # on its back, which never ends an episode
}
"""Per task, a qpos entry and a value that make a state Brax's health rule calls a fall."""

MJX_FAST_COMPILE = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True}
"""About a third off an MJX step's compile here; the test compares to float32 drift anyway."""


def test_every_brax_task_has_a_module_and_checked_options():
    """The four locomotion tasks are registered, and each C model carries MJX's options where
    Brax changed them (Ant: Newton, 1 iteration, 4 line searches, Euler damping off), the XML's
    float64 values elsewhere."""
    from arld_jax.physics import _c_model

    assert set(BRAX_TASKS) >= {"halfcheetah", "hopper", "walker2d", "ant"}
    for name in BRAX_TASKS:
        sys = load_brax_env(REGISTRY[name].brax_name, "mjx").sys
        model = _c_model(sys)
        for field in ("solver", "iterations", "ls_iterations", "disableflags", "cone"):
            assert getattr(model.opt, field) == int(getattr(sys.opt, field)), (name, field)
        for field in ("timestep", "tolerance", "impratio", "gravity"):
            np.testing.assert_allclose(
                getattr(model.opt, field), getattr(sys.opt, field), rtol=1e-6, err_msg=field
            )
        assert model.opt.timestep == sys.mj_model.opt.timestep  # float64, not float32's
    ant = _c_model(load_brax_env("ant", "mjx").sys)
    assert (ant.opt.iterations, ant.opt.ls_iterations) == (1, 4)


def _c_obs(env, steps: int):
    """The observations of 2 C-engine envs after `steps` uniform-random actions from a fixed reset
    (the same states and actions for every `env` of a task)."""
    state = jax.jit(env.reset, static_argnums=1)(jax.random.key(6), 2)
    step = jax.jit(env.step)
    for i in range(steps):
        shape = (2, env.action_dim)
        state = step(state, jax.random.uniform(jax.random.key(i), shape, minval=-1.0, maxval=1.0))
    return np.asarray(state.obs)


def _mjx_step(env) -> str:
    """The traced MJX step of 2 envs of `env`, as text: equal exactly when the step is the same."""
    state = jax.eval_shape(lambda k: env.reset(k, 2), jax.random.key(0))
    return str(jax.make_jaxpr(env.step)(state, jnp.zeros((2, env.action_dim))))


def test_solver_options_reach_both_engines():
    """`--solver_iterations` / `--solver_ls_iterations` set MuJoCo's solver on both backends: Ant
    with its own options given explicitly (1 iteration, 4 line searches) is the default Ant, bit
    for bit on the C engine and as the same traced MJX step; with MuJoCo's defaults (100, 50) the
    C engine's steps from the same states differ, and MJX traces a different step."""

    def ant(backend, iterations, ls_iterations):
        cfg = Config(
            env_name="ant",
            backend=backend,
            solver_iterations=iterations,
            solver_ls_iterations=ls_iterations,
        )
        return make_env(cfg)

    # 20 steps: enough for the feet to land; contacts are what the solver solves.
    own, explicit, mujoco = (_c_obs(ant("mujoco", *s), 20) for s in ((0, 0), (1, 4), (100, 50)))
    np.testing.assert_array_equal(explicit, own)
    assert float(np.max(np.abs(mujoco - own))) > 1e-4

    own, explicit, mujoco = (_mjx_step(ant("mjx", *s)) for s in ((0, 0), (1, 4), (100, 50)))
    assert explicit == own and mujoco != own


def test_integrator_reaches_both_engines():
    """`--integrator rk4` sets MuJoCo's RK4 on both backends: the C engine's model integrates with
    mjINT_RK4 and its steps from the same states differ from Euler's; MJX traces a different step."""
    import mujoco

    from arld_jax.config import INTEGRATOR_OPT
    from arld_jax.physics import _c_model

    assert INTEGRATOR_OPT == {"rk4": int(mujoco.mjtIntegrator.mjINT_RK4)}

    def hopper(backend, integrator):
        return make_env(Config(env_name="hopper", backend=backend, integrator=integrator))

    euler, rk4 = (_c_obs(hopper("mujoco", i), 10) for i in ("task", "rk4"))
    assert np.all(np.isfinite(rk4)) and float(np.max(np.abs(rk4 - euler))) > 1e-4
    sys = load_brax_env("hopper", "mjx").sys
    rk4_sys = sys.tree_replace({"opt.integrator": INTEGRATOR_OPT["rk4"]})
    assert _c_model(sys).opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert _c_model(rk4_sys).opt.integrator == mujoco.mjtIntegrator.mjINT_RK4

    assert _mjx_step(hopper("mjx", "rk4")) != _mjx_step(hopper("mjx", "task"))


def _upside_down(state, height: float):
    """The C-engine Ant state `state` turned on its back (half a turn about x), its torso at
    `height`."""
    host = state.inner.pipeline_state
    q = host.q.at[:, 2].set(height).at[:, 3:7].set(jnp.array([0.0, 1.0, 0.0, 0.0]))
    return state.replace(inner=state.inner.replace(pipeline_state=host.replace(q=q)))


def test_all_contacts_reach_both_engines():
    """`--contacts all` lets every body geom meet the floor on both backends. An Ant dropped on its
    back: with Brax's contacts (its feet only) the torso sinks through the floor and the episode
    ends by a fall in a few steps; with all contacts it comes to rest on its torso at the torso's
    radius (0.25), which Brax's health rule (0.2 <= z <= 1.0) calls healthy, for 100 steps. MJX's
    state holds a contact per geom pair that can touch: the 4 feet with Brax's contacts, and the
    torso's and two per leg capsule more with all (29)."""
    radius = float(load_brax_env("ant", "mjx").sys.geom_size[1, 0])  # the torso sphere's
    heights, ended = {}, {}
    for contacts in CONTACTS:
        env = make_env(Config(env_name="ant", backend="mujoco", contacts=contacts))
        state = _upside_down(jax.jit(env.reset, static_argnums=1)(jax.random.key(0), 2), 0.3)
        step = jax.jit(env.step)
        ended[contacts] = []
        for _ in range(100):
            state = step(state, jnp.zeros((2, env.action_dim)))
            ended[contacts].append(np.asarray(state.terminated))
        heights[contacts] = np.asarray(state.inner.pipeline_state.q[:, 2])
    assert 0 < np.argmax(np.any(ended["task"], axis=1)) < 10 and heights["task"].max() < 0.0
    assert not np.any(ended["all"])
    np.testing.assert_allclose(heights["all"], radius, atol=2e-3)

    def mjx_contacts(contacts):
        mjx = make_env(Config(env_name="ant", backend="mjx", contacts=contacts))
        state = jax.eval_shape(lambda k: mjx.reset(k, 2), jax.random.key(0))
        return state.inner.pipeline_state.contact.dist.shape[-1]

    assert (mjx_contacts("task"), mjx_contacts("all")) == (4, 29)


def test_all_contacts_on_the_c_engine_are_those_of_a_model_compiled_with_them():
    """The C engine's Ant with `--contacts all` (Brax's compiled model, its collision arrays
    changed) finds the same contacts as Brax's ant.xml compiled with every body geom's contype 1:
    all 17 body geoms on a floor 0.05 below the torso's centre, two per capsule (29). With the
    model's mid phase on, whose trees were built for the feet alone, it would miss the capsules that
    share a body with a foot."""
    import os

    import brax
    import mujoco

    from arld_jax.physics import _c_model, all_geoms_touch_floor

    spec = mujoco.MjSpec.from_file(
        os.path.join(os.path.dirname(brax.__file__), "envs/assets/ant.xml")
    )
    spec.compiler.fusestatic = True  # as Brax loads it: bodies without joints merged
    for geom in spec.geoms:
        if geom.parent.name != "world":
            geom.contype = 1
    compiled = spec.compile()
    ours = _c_model(all_geoms_touch_floor(load_brax_env("ant", "mjx").sys))

    def contacts(model):
        data = mujoco.MjData(model)
        data.qpos[:] = compiled.qpos0
        data.qpos[2] = 0.05  # torso and legs (radius 0.08) below the floor's surface
        mujoco.mj_forward(model, data)
        return sorted((c.geom1, c.geom2, round(float(c.dist), 6)) for c in data.contact)

    assert contacts(ours) == contacts(compiled)
    assert len(contacts(ours)) == 29 and {g for _, g, _ in contacts(ours)} == set(range(1, 18))


def test_a_wrong_task_name_is_refused_with_the_task_list():
    """`Config.env_name`'s choices are the task modules (a new task is one module)."""
    assert tuple(REGISTRY) == ENVS
    with pytest.raises(ValueError, match="env_name = 'cheetah' is invalid: allowed one of") as info:
        Config(env_name="cheetah")
    for name in ("'halfcheetah'", "'hopper'", "'walker2d'", "'ant'", "'toy_fall'"):
        assert name in str(info.value)


def _c_state_after(env, key, steps: int, n: int = 2):
    """A C-engine state of `n` envs reached by `steps` uniform-random steps from a reset."""
    state = jax.jit(env.reset, static_argnums=1)(key, n)
    step = jax.jit(env.step)
    for k in jax.random.split(jax.random.fold_in(key, 1), steps):
        state = step(state, jax.random.uniform(k, (n, env.action_dim), minval=-1.0, maxval=1.0))
    return state


def _as_mjx_state(mjx_env, c_state):
    """MJX's EnvState holding the C state's physics (qpos, qvel, warm start, bodies' frames)."""
    n = c_state.obs.shape[0]
    template = jax.eval_shape(lambda k: mjx_env.reset(k, n), jax.random.key(0))
    zeros = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), template)
    host = c_state.inner.pipeline_state
    physics = zeros.inner.pipeline_state.replace(
        qpos=host.q,
        qvel=host.qd,
        qacc_warmstart=host.qacc_warmstart,
        q=host.q,
        qd=host.qd,
        x=host.x,
    )
    inner = zeros.inner.replace(pipeline_state=physics, obs=c_state.obs)
    return zeros.replace(inner=inner, obs=c_state.obs)


@slow
@pytest.mark.parametrize("task", BRAX_TASKS)
def test_both_backends_give_the_same_step(task):
    """From the same state (reached by a few random C steps: bodies moving, feet on the ground)
    and the same action, one step of each backend gives the same observation (contact forces too,
    where the task observes them) and reward to float32 drift and the same termination: 0 on that
    healthy state, and on a constructed unhealthy one (`UNHEALTHY`) 1 for a task that can fall, 0
    for HalfCheetah. Compiles one MJX step."""
    c = make_env(Config(env_name=task, backend="mujoco"))
    mjx = make_env(Config(env_name=task, backend="mjx"))
    assert (c.obs_dim, c.action_dim, c.can_terminate) == (
        mjx.obs_dim,
        mjx.action_dim,
        mjx.can_terminate,
    )
    assert c.can_terminate == REGISTRY[task].can_terminate == (task != "halfcheetah")
    healthy = _c_state_after(c, jax.random.key(3), steps=3)
    index, value = UNHEALTHY[task]
    host = healthy.inner.pipeline_state
    fallen_q = host.q.at[:, index].set(value)
    fallen = healthy.replace(inner=healthy.inner.replace(pipeline_state=host.replace(q=fallen_q)))
    action = jax.random.uniform(jax.random.key(4), (2, c.action_dim), minval=-1.0, maxval=1.0)
    step_c = jax.jit(c.step)
    step_m = jax.jit(mjx.step, compiler_options=MJX_FAST_COMPILE)
    for name, state, fell in (("healthy", healthy, 0.0), ("unhealthy", fallen, 1.0)):
        sc = step_c(state, action)
        sm = step_m(_as_mjx_state(mjx, state), action)
        np.testing.assert_allclose(sc.obs, sm.obs, rtol=1e-4, atol=5e-4, err_msg=name)
        np.testing.assert_allclose(sc.reward, sm.reward, rtol=1e-4, atol=5e-4, err_msg=name)
        expected = fell if c.can_terminate else 0.0
        np.testing.assert_array_equal(sc.terminated, [expected] * 2, err_msg=name)
        np.testing.assert_array_equal(sm.terminated, [expected] * 2, err_msg=name)
        assert float(jnp.max(jnp.abs(sc.obs - state.obs))) > 1e-3  # it moved
        if REGISTRY[task].contact_forces and name == "healthy":  # a foot on the floor
            forces = sm.obs[:, -6 * host.x.pos.shape[1] :]
            assert float(jnp.sum(jnp.abs(forces))) > 1.0, name
    assert float(jnp.max(jnp.abs(sc.obs - sm.obs))) > 0  # two engines, not one


@pytest.mark.parametrize("task", ["halfcheetah", "hopper", "walker2d", "ant"])
def test_c_engine_reward_is_brax_formula(task):
    """On the C engine, Brax's reward from the host's frames: forward velocity of the torso
    (x' - x) / dt, plus 1 per step alive for the tasks that can fall, minus the control cost
    (weights from brax/envs/*.py: HalfCheetah 0.1, Hopper and Walker2d 0.001, Ant 0.5); and the
    frames' torso x moves as qpos's root x does where the root is a slide along x."""
    env = make_env(Config(env_name=task, backend="mujoco"))
    brax_env = load_brax_env(REGISTRY[task].brax_name, "mjx")
    state = _c_state_after(env, jax.random.key(5), steps=2, n=4)
    action = jnp.linspace(-1.0, 1.0, 4 * env.action_dim).reshape(4, env.action_dim)
    nxt = jax.jit(env.step)(state, action)
    x0, x1 = (s.inner.pipeline_state.x.pos[:, 0, 0] for s in (state, nxt))
    velocity = (x1 - x0) / float(brax_env.dt)
    ctrl = {"halfcheetah": 0.1, "hopper": 1e-3, "walker2d": 1e-3, "ant": 0.5}[task]
    alive = 1.0 if env.can_terminate else 0.0
    expected = velocity + alive - ctrl * jnp.sum(action**2, axis=-1)
    np.testing.assert_allclose(nxt.reward, expected, rtol=1e-4, atol=1e-4)
    assert float(jnp.max(jnp.abs(velocity))) > 0.01  # the torso moved: the velocity term was tested


def test_contact_forces_need_a_mujoco_backend():
    """A task observing contact forces is refused on Brax's own pipelines, which compute none,
    before anything is built; Brax's Ant is not."""
    with pytest.raises(ValueError, match="backend = 'generalized' is invalid: allowed 'mjx' or"):
        Config(env_name="ant_contact", backend="generalized")
    assert Config(env_name="ant", backend="generalized").backend == "generalized"


def test_ant_contact_is_ant_with_mujocos_contact_forces():
    """`ant_contact` on the C engine, against MuJoCo itself and Brax's Ant: from the same state and
    action, its observation is Ant's 27 then cfrc_ext[1:] clipped to [-1, 1] as MuJoCo computes it
    after the step (`mj_step` of 5 frames, then `mj_rnePostConstraint`, as Gymnasium's Ant-v5 does),
    and its reward is Ant's less 5e-4 x their sum of squares; a reset observes the forces at the
    initial state (`mj_forward`), and its reward stays 0."""
    import mujoco

    from arld_jax.physics import _c_model

    ant = make_env(Config(env_name="ant", backend="mujoco"))
    contact = make_env(Config(env_name="ant_contact", backend="mujoco"))
    model = _c_model(load_brax_env("ant", "mjx").sys)
    bodies = model.nbody - 1
    assert contact.obs_dim == ant.obs_dim + 6 * bodies == 27 + 54
    state = _c_state_after(contact, jax.random.key(6), steps=4, n=8)
    action = jnp.linspace(-1.0, 1.0, 8 * 8).reshape(8, 8)
    got = jax.jit(contact.step)(state, action)
    host = state.inner.pipeline_state
    ant_state = _c_state_after(ant, jax.random.key(6), steps=4, n=8)
    np.testing.assert_array_equal(ant_state.inner.pipeline_state.q, host.q)  # the same physics
    plain = jax.jit(ant.step)(ant_state, action)
    data = mujoco.MjData(model)
    want = []
    for e in range(8):
        data.qpos[:], data.qvel[:] = host.q[e], host.qd[e]
        data.qacc_warmstart[:], data.ctrl[:] = host.qacc_warmstart[e], action[e]
        mujoco.mj_step(model, data, nstep=5)
        mujoco.mj_rnePostConstraint(model, data)
        want.append(np.clip(data.cfrc_ext[1:], -1.0, 1.0).ravel())
    want = np.stack(want)
    np.testing.assert_array_equal(got.obs[:, :27], plain.obs)
    np.testing.assert_allclose(got.obs[:, 27:], want, atol=1e-6)
    cost = 5e-4 * np.sum(want**2, axis=-1)
    np.testing.assert_allclose(got.reward, plain.reward - cost, atol=1e-6)
    # Some envs touch the floor after the step (Ant bounces on random actions), some forces clipped.
    assert (cost > 1e-3).sum() >= 2 and np.abs(want).max() == 1.0
    np.testing.assert_array_equal(got.terminated, plain.terminated)
    fresh = contact.reset(jax.random.key(7), 2)
    for e in range(2):
        data.qpos[:], data.qvel[:] = (
            fresh.inner.pipeline_state.q[e],
            fresh.inner.pipeline_state.qd[e],
        )
        data.qacc_warmstart[:], data.ctrl[:] = 0.0, 0.0
        mujoco.mj_forward(model, data)
        mujoco.mj_rnePostConstraint(model, data)
        np.testing.assert_allclose(
            fresh.obs[e, 27:], np.clip(data.cfrc_ext[1:], -1, 1).ravel(), atol=1e-6
        )
    np.testing.assert_array_equal(fresh.reward, 0.0)


# ---------------------------------------------------------------- batching


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
    # A fresh wrapper: jax (0.11) keeps the unbatched trace of a custom_vmap it has traced before.
    jax.make_jaxpr(limit_batch(step, 4))(states[0], actions[0])
    assert seen == [2]


# ---------------------------------------------------------------- third-party notices


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


def test_third_party_noise_is_dropped_at_python_level(capsys):
    """Also when `sys.stdout` is not file descriptor 1 (pytest's capsys, a notebook): MJX's Warp
    message is a Python `print`."""
    from arld_jax.envs import without_third_party_noise

    with without_third_party_noise():
        print("Failed to import mujoco_warp: No module named 'warp'")
        print("a message of our own")
    out, err = capsys.readouterr()
    assert "warp" not in out + err and "a message of our own" in out + err


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


# ---------------------------------------------------------------- the C step is pure


@pytest.fixture(scope="module")
def c_env():
    return make_env(Config(backend="mujoco"))


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
