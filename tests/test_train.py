"""The scanned loop on the toy env: learning, seeds under vmap, one trace, expert queries in the loop."""

from __future__ import annotations

import re

import jax
import jax.experimental
import jax.numpy as jnp
import numpy as np
import pytest

from arld_jax.compile import jit_chunk, over_runs, unroll_threefry_on_cpu
from arld_jax.config import hparams_from_config, tiny
from arld_jax.envs import toy_target_action
from arld_jax.expert import toy_expert
from arld_jax.rundir import is_key
from arld_jax.sweep import Sweep
from arld_jax.train import make_train, only_if

TOY_EXPERT = toy_expert()
SEEDS = (0, 1, 2)
TOL = 1e-3  # vmapped-vs-single tolerance, see test_vmapped_seed_equals_single_run


def _stack(hps):
    return jax.tree.map(lambda *xs: jnp.stack(xs), *hps)


@pytest.fixture(scope="session")
def toy_sweep():
    """One compiled program: 3 strategies x 3 seeds of the tiny toy config with the toy expert."""
    cfg = tiny(budget=150, demo_steps=3, query_prob=0.2, t_query=0.2)
    trainer = make_train(cfg, TOY_EXPERT)
    strategies = ("none", "greedy", "bernoulli", "active")
    configs = [cfg.replace(strategy=s, seed=k) for s in strategies for k in SEEDS]
    hps = _stack([hparams_from_config(c) for c in configs])
    keys = jnp.stack([jax.random.key(c.seed) for c in configs])
    state, metrics = jax.jit(jax.vmap(trainer.train))(keys, hps)
    return cfg, trainer, configs, state, metrics


def test_eval_return_improves_over_untrained_start(toy_sweep):
    cfg, trainer, configs, state, metrics = toy_sweep
    plain = [i for i, c in enumerate(configs) if c.strategy == "none"]
    untrained = jax.vmap(trainer.init)(
        jnp.stack([jax.random.key(configs[i].seed) for i in plain]),
        _stack([hparams_from_config(configs[i]) for i in plain]),
    )
    start = jax.vmap(trainer.evaluate)(
        untrained.agent, jax.random.split(jax.random.key(9), len(plain))
    ).episode_return
    final = np.asarray(metrics.eval_return)[plain, -1]
    # Toy env: best policy earns 1 per step (50 per episode), a random-ish start well below.
    assert np.all(final > np.asarray(start) + 5.0), (final, start)
    assert np.all(final > 0.85 * cfg.episode_length)
    # Losses are finite and the critic fits: last-period loss below the first learning period's.
    critic = np.asarray(metrics.critic_loss)[plain]
    assert np.all(np.isfinite(critic)) and np.all(critic[:, -1] < critic[:, 0])


def test_vmapped_seed_equals_single_run():
    """Seed k inside a vmapped sweep = a single run with seed k, to float tolerance. The horizon is
    short on purpose: batched matmuls round differently, and RL training amplifies any difference
    chaotically over thousands of updates (bit-equality is not on offer from XLA). Measured at
    500 steps: vmapped and single agree to ~5e-7. At 600 steps (eval every 300) they split abruptly at
    step 474 -- a discrete event (a replay sample drawn across a sum-tree boundary that rounding
    moved), after which the runs are different trajectories; so the horizon stays short."""
    cfg = tiny(total_env_steps=500, eval_every=250, learning_starts=100, budget=60, demo_steps=2)
    trainer = make_train(cfg, TOY_EXPERT)
    configs = [
        cfg.replace(strategy=s, seed=k) for s, k in (("active", 0), ("greedy", 1), ("none", 2))
    ]
    hps = _stack([hparams_from_config(c) for c in configs])
    keys = jnp.stack([jax.random.key(c.seed) for c in configs])
    state, metrics = jax.jit(jax.vmap(trainer.train))(keys, hps)
    i = 1
    single_state, single = jax.jit(trainer.train)(
        jax.random.key(configs[i].seed), hparams_from_config(configs[i])
    )
    for name in ("eval_return", "critic_loss", "demos_used", "uncertainty_trace"):
        np.testing.assert_allclose(
            np.asarray(getattr(metrics, name))[i],
            np.asarray(getattr(single, name)),
            rtol=TOL,
            atol=TOL,
            err_msg=name,
        )
    np.testing.assert_allclose(
        np.asarray(state.replay.data.action)[i],
        np.asarray(single_state.replay.data.action),
        atol=TOL,
    )
    # And the other runs lie outside that tolerance (the comparison is not vacuous).
    for j in (0, 2):
        assert not np.allclose(
            np.asarray(metrics.critic_loss)[j], np.asarray(single.critic_loss), rtol=TOL, atol=TOL
        )


def test_budget_and_demo_flags_in_the_loop(toy_sweep):
    cfg, trainer, configs, state, metrics = toy_sweep
    demos = np.asarray(metrics.demos_used)[:, -1]
    data = state.replay.data
    is_demo = np.asarray(data.is_demo) > 0.5  # [runs, capacity]; capacity == total steps here
    for i, c in enumerate(configs):
        assert demos[i] <= cfg.budget
        assert is_demo[i].sum() == demos[i]
        if c.strategy == "none":
            assert demos[i] == 0
        if c.strategy == "greedy":
            # Greedy spends the budget first and exactly: with 2 envs and C-step runs, only the last
            # run may be cut short, so demos fill the start of the replay (envs interleave in it).
            slack = cfg.num_envs * cfg.demo_steps
            assert demos[i] == cfg.budget
            assert is_demo[i, : cfg.budget - slack].all()
            assert not is_demo[i, cfg.budget + slack :].any()
    # Where the mask is set the stored (executed) action is the expert's, elsewhere the agent's.
    obs, action = np.asarray(data.obs), np.asarray(data.action)
    expert = np.asarray(toy_target_action(jnp.asarray(obs)))
    np.testing.assert_allclose(action[is_demo], expert[is_demo], atol=1e-5)
    agent_steps = ~is_demo & (np.arange(cfg.replay_capacity) >= cfg.learning_starts)
    assert np.mean(np.abs(action[agent_steps] - expert[agent_steps]).max(-1) > 1e-3) > 0.5


def _query_starts(is_demo: np.ndarray, length: int, c: int) -> np.ndarray:
    """[T, E] bool: the iterations where each env's expert runs started, read from its is_demo
    flags [T, E]. A run granted at iteration t lasts min(C, steps left in the episode); only the
    budget's last run may be shorter, and nothing follows it, so skipping min(C, left) is exact."""
    starts = np.zeros_like(is_demo)
    for e in range(is_demo.shape[1]):
        t = 0
        while t < is_demo.shape[0]:
            if is_demo[t, e]:
                starts[t, e] = True
                t += min(c, length - t % length)
            else:
                t += 1
    return starts


def _free_budget(starts: np.ndarray, length: int, c: int, budget: int) -> np.ndarray:
    """[T, E] the budget not yet reserved when env e decides at iteration t: queries are granted in
    (iteration, env) order, each reserving its whole run of min(C, steps left) steps."""
    left = length - np.arange(starts.shape[0]) % length
    reserved = (starts * np.minimum(c, left)[:, None]).ravel()
    return budget - (np.cumsum(reserved) - reserved).reshape(starts.shape)


def _loop_queries(cfg, state, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run i's query starts, decision steps (the env not inside an expert run) and free budget,
    all [iterations, envs], from its replay (which holds every step here; items alternate envs)."""
    assert cfg.replay_capacity == cfg.total_env_steps
    is_demo = np.asarray(state.replay.data.is_demo)[i].reshape(-1, cfg.num_envs) > 0.5
    starts = _query_starts(is_demo, cfg.episode_length, cfg.demo_steps)
    free = _free_budget(starts, cfg.episode_length, cfg.demo_steps, cfg.budget)
    return starts, ~is_demo | starts, free


def test_query_counts_in_the_loop(toy_sweep):
    """How often each strategy asks, read from the replay and checked against each rule's count.
    (The active rule is checked step by step in the next test.)"""
    cfg, trainer, configs, state, metrics = toy_sweep
    queries = np.asarray(metrics.queries)  # [runs, periods]
    bernoulli_trials, bernoulli_queries = 0, 0
    for i, c in enumerate(configs):
        starts, decision, free = _loop_queries(cfg, state, i)
        # The period metric counts the query starts that the replay shows.
        per_period = starts.reshape(cfg.num_evals, cfg.iters_per_eval, -1).sum(axis=(1, 2))
        np.testing.assert_array_equal(queries[i], per_period, err_msg=str(i))
        grantable = decision & (free > 0)
        if c.strategy == "none":
            assert not starts.any()
        if c.strategy == "greedy":
            # Asks at every decision step while budget is left: 2 envs, C = 3, episodes of 50 =
            # 16 runs of 3 and one of 2 per env and episode (100 demos in episode 1); then 8 runs
            # of 3 per env (48 demos) and a last run of 2 for env 0: 34 + 16 + 1 = 51 queries,
            # 150 = budget demos, all in the first 75 iterations (period 0).
            np.testing.assert_array_equal(starts, grantable)
            assert starts.sum() == 51 and not starts[75:].any()
            np.testing.assert_array_equal(queries[i], [51, 0, 0, 0])
        if c.strategy == "bernoulli":
            bernoulli_trials += int(grantable.sum())
            bernoulli_queries += int(starts[grantable].sum())
            assert not starts[~grantable].any()
    # BQSAC: at each decision step with budget left, a query starts iff a fresh uniform draw is
    # below b. Those steps are chosen by the past only, so the queries minus b per trial is a
    # martingale: over n trials, queries has mean b n and sd sqrt(b (1 - b) n) (n is about 850
    # over the 3 seeds, b = 0.2: 170 +- 11.7). Bound: 3 sd.
    b, n = cfg.query_prob, bernoulli_trials
    assert n > 600, n
    assert abs(bernoulli_queries - b * n) < 3 * np.sqrt(b * (1 - b) * n), (bernoulli_queries, n)


def test_active_queries_where_u_ranks_in_the_top_t_query(toy_sweep):
    """AQSAC in the loop, step by step through the warm-up: the agent's parameters are its initial
    ones there, so u(s) = sigma_theta(s) of every stored state can be recomputed; the reference
    window holds the last N_r = 50 values of u over all envs, and at every decision step with budget
    left a query starts iff fewer than t_query N_r = 10 of them are strictly above u.

    Where exactly 10 of 50 are above (fraction == t_query) the float comparison 10 / 50 < 0.2 is
    decided by how XLA rounds the division (the loop has asked there), so those steps are left out."""
    cfg, trainer, configs, state, metrics = toy_sweep
    warm = cfg.warmup_iters  # 100 iterations of 2 envs
    obs = np.asarray(state.replay.data.obs)
    checked, asked = 0, 0
    for i, c in enumerate(configs):
        if c.strategy != "active":
            continue
        hp = hparams_from_config(c)
        agent = trainer.init(jax.random.key(c.seed), hp).agent
        stored = jnp.asarray(obs[i, : warm * cfg.num_envs])
        u = np.asarray(trainer.agent.act(agent, stored, jax.random.key(0), hp).uncertainty)
        u = u.reshape(warm, cfg.num_envs)
        starts, decision, free = _loop_queries(cfg, state, i)
        for t in range(warm):
            window = u[:t].ravel()[-cfg.window_size :]
            for e in range(cfg.num_envs):
                if not decision[t, e] or free[t, e] <= 0 or window.size == 0:
                    assert not starts[t, e], (i, t, e)  # inside a run, no budget, empty window
                    continue
                above = int(np.sum(window > u[t, e]))
                if above == c.t_query * window.size:
                    continue
                want = above < c.t_query * window.size
                assert starts[t, e] == want, (i, t, e, above, window.size)
                checked += 1
                asked += want
    assert checked > 300 and 20 < asked < checked / 2, (checked, asked)


def test_sigma_theta_falls_as_sac_learns(toy_sweep):
    """The policy's mean sigma_theta(s) on visited states falls in every period of the plain (no
    query) runs: from about 1 while it explores to about 0.67 at the end."""
    cfg, trainer, configs, state, metrics = toy_sweep
    plain = [i for i, c in enumerate(configs) if c.strategy == "none"]
    sigma = np.asarray(metrics.sigma)[plain]  # [runs, periods]
    assert np.all(np.diff(sigma, axis=1) < 0), sigma
    assert np.all(sigma[:, -1] < 0.85 * sigma[:, 0]), sigma
    # Uncertainty traces are recorded for every run and finite.
    trace = np.asarray(metrics.uncertainty_trace)
    assert trace.shape == (len(configs), cfg.num_evals, cfg.traces_per_eval)
    assert np.all(np.isfinite(trace))


def test_state_samples_hold_visited_and_queried_states(toy_sweep):
    cfg, trainer, configs, state, metrics = toy_sweep
    valid_visited = np.asarray(state.visited.key) >= 0
    valid_queried = np.asarray(state.queried.key) >= 0
    assert valid_visited.all()  # 2,000 visited states >> 32 slots
    for i, c in enumerate(configs):
        if c.strategy == "none":
            assert not valid_queried[i].any()
        else:
            assert valid_queried[i].any()
    # Samples are spread over the run, not just its end (uniform reservoir).
    steps = np.asarray(state.visited.env_step)[0]
    assert steps.min() < cfg.total_env_steps / 4 and steps.max() > cfg.total_env_steps * 3 / 4


def test_run_periods_traces_once():
    cfg = tiny(total_env_steps=1_000, eval_every=250, learning_starts=100)
    trainer = make_train(cfg)
    traces = []

    def counted(state, hp, first):
        traces.append(1)
        return trainer.run_periods(state, hp, first, 1)

    run = jax.jit(counted)
    hp = hparams_from_config(cfg)
    state = trainer.init(jax.random.key(0), hp)
    for p in range(cfg.num_evals):
        state, m = run(state, hp.replace(critic_lr=hp.critic_lr * (p + 1)), jnp.int32(p))
    assert len(traces) == 1
    assert int(m.env_steps[-1]) == cfg.total_env_steps


def test_no_expert_refuses_query_strategies():
    cfg = tiny(total_env_steps=1_000, eval_every=500)
    trainer = make_train(cfg)
    hp = hparams_from_config(cfg.replace(strategy="active"))
    with pytest.raises(ValueError, match="needs an expert"):
        trainer.train(jax.random.key(0), hp)
    # Also when one run of a batch of hyperparameters asks (the check reads the whole array).
    mixed = _stack([hparams_from_config(cfg.replace(strategy=s)) for s in ("none", "bernoulli")])
    with pytest.raises(ValueError, match="needs an expert"):
        trainer.train(jax.random.key(0), mixed)


def test_update_before_add_learns_and_keeps_demos():
    """`update_before_add` (updates on the replay before this iteration's transitions) is a
    performance option: it must still learn the toy task and mark the expert's steps as demos."""
    cfg = tiny(update_before_add=True, strategy="greedy", budget=100)
    trainer = make_train(cfg, TOY_EXPERT)
    hp = hparams_from_config(cfg)
    state, metrics = jax.jit(trainer.train)(jax.random.key(0), hp)
    final = float(metrics.eval_return[-1])
    assert final > 0.85 * cfg.episode_length, final
    assert int(metrics.demos_used[-1]) == cfg.budget
    assert float(jnp.sum(state.replay.data.is_demo)) == cfg.budget
    assert int(state.replay.size) == cfg.replay_capacity


def test_only_if_runs_its_function_exactly_when_asked():
    carry = {"a": jnp.arange(3.0), "n": jnp.int32(4)}
    double = lambda c: jax.tree.map(lambda x: 2 * x, c)  # noqa: E731
    run = jax.jit(only_if, static_argnums=1)
    for pred, factor in ((True, 2), (False, 1)):
        out = run(jnp.asarray(pred), double, carry)
        np.testing.assert_array_equal(out["a"], factor * np.arange(3.0))
        assert int(out["n"]) == 4 * factor
    # Under vmap over the carry with an unbatched predicate, every row follows the predicate.
    rows = {"a": jnp.ones((2, 3)), "n": jnp.array([1, 2], jnp.int32)}
    out = jax.vmap(lambda c: only_if(jnp.asarray(True), double, c))(rows)
    np.testing.assert_array_equal(out["n"], [2, 4])


def _loop_copies(hlo: str) -> list[tuple[int, ...]]:
    """Shapes of the `copy` instructions in loop bodies and branches of an optimized HLO module.

    Copies inside fusions (layout changes within one kernel) and in the entry computation (once
    per call) are left out: what is left runs at every iteration."""
    shapes, comp = [], ""
    for line in hlo.splitlines():
        if line and not line[0].isspace() and line.rstrip().endswith("{"):
            comp = "ENTRY" if line.startswith("ENTRY") else line.split()[0]
            continue
        m = re.match(r"\s*(?:ROOT )?%?[\w.\-]+ = \w+\[([\d,]*)\]\S* copy\(", line)
        if m and comp != "ENTRY" and "fused" not in comp and "wrapped" not in comp:
            shapes.append(tuple(int(d) for d in m.group(1).split(",") if d))
    return shapes


def test_a_run_axis_of_one_is_squeezed_not_vmapped():
    """`over_runs` vmaps over runs, except a run axis of size 1, which it squeezes: the function
    then sees unbatched arrays (an ordered host callback, which vmap refuses, works) and its
    outputs get the run axis back."""
    seen = []

    def fn(x, y):  # noqa: ANN001, ANN202
        jax.experimental.io_callback(lambda v: seen.append(np.asarray(v)), None, x, ordered=True)
        return {"sum": x + y, "y": y}

    one = jax.jit(over_runs(fn, in_axes=(0, None)))(jnp.ones((1, 3)), jnp.float32(2.0))
    assert one["sum"].shape == (1, 3) and one["y"].shape == (1,)
    np.testing.assert_array_equal(one["sum"], 3.0)
    assert len(seen) == 1 and seen[0].shape == (3,)  # unbatched inside
    with pytest.raises(Exception, match="(?i)vmap"):
        jax.jit(over_runs(fn, in_axes=(0, None)))(jnp.ones((2, 3)), jnp.float32(2.0))


@pytest.mark.parametrize("num_runs", [1, 2])
def test_compiled_loop_copies_neither_the_replay_nor_the_agent_state(num_runs: int):
    """Performance structure, not timing: in the chunk that run.py compiles (seed-vmapped; a single
    run squeezed, `over_runs`), XLA must update the replay and the AgentState in place.
    Regressions this catches (each seen before, benchmarks/README.md): a `lax.cond` around
    the update copied the whole AgentState at every iteration (about 2x its size in loop copies
    here), and without `compiler_options()` the sum tree was copied in the loop (at 1M x 8 seeds
    that made the replay work 12x slower)."""
    cfg = tiny(replay_capacity=5_000, hidden_sizes=(64, 64))
    trainer = make_train(cfg)
    hps = _stack([hparams_from_config(cfg)] * num_runs)
    state = jax.jit(jax.vmap(trainer.init))(jax.random.split(jax.random.key(0), num_runs), hps)
    run = jit_chunk(trainer, donate=False)
    compiled = run.lower(state, hps, jnp.int32(0), 1).compile()
    copies = _loop_copies(compiled.as_text())
    replay_shapes = {tuple(x.shape) for x in jax.tree.leaves(state.replay) if x.ndim > 1}
    assert not [s for s in copies if s in replay_shapes], (copies, replay_shapes)
    agent_elements = sum(x.size for x in jax.tree.leaves(state.agent))
    copied = sum(int(np.prod(s)) for s in copies)
    assert copied < 0.5 * agent_elements, (copied, agent_elements, copies)
    # The options change which buffers are copied, never a result: same numbers as without them.
    plain = jax.jit(over_runs(trainer.run_periods, in_axes=(0, 0, None, None)), static_argnums=3)
    _, want = plain(state, hps, jnp.int32(0), 1)
    _, got = compiled(state, hps, jnp.int32(0))
    for name in ("eval_return", "critic_loss", "actor_loss", "uncertainty_trace"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))


def test_an_expert_that_hands_back_spends_no_budget_and_adds_no_demo():
    """An expert answering NaN for env 0 declines its queries (a person's "hand back"): env 0's
    steps stay the agent's, not is_demo, and only env 1's demonstrated steps are spent. (Greedy
    asks env 0 first at every step, so the last unit of budget goes to env 0 and comes back each
    time: env 1 gets budget - 1 steps.)"""
    cfg = tiny(strategy="greedy", budget=60, total_env_steps=1000, eval_every=500)

    def act(params, obs, key, context=None):  # noqa: ANN001, ANN202
        action = toy_target_action(obs)
        return action.at[0].set(jnp.nan)

    expert = toy_expert()._replace(act=act)
    trainer = make_train(cfg, expert)
    state, metrics = jax.jit(trainer.train)(jax.random.key(0), hparams_from_config(cfg))
    assert int(metrics.demos_used[-1]) == cfg.budget - 1
    size = int(state.replay.size)
    is_demo = np.asarray(state.replay.data.is_demo)[:size]
    action = np.asarray(state.replay.data.action)[:size]
    obs = np.asarray(state.replay.data.obs)[:size]
    assert not np.any(np.isnan(action))
    assert int(is_demo.sum()) == cfg.budget - 1
    # The demonstrated items are env 1's expert actions (items alternate env 0, env 1).
    np.testing.assert_array_equal(np.flatnonzero(is_demo) % 2, 1)
    demo = is_demo == 1
    np.testing.assert_allclose(action[demo], np.asarray(toy_target_action(obs[demo])), atol=1e-6)


@pytest.mark.parametrize("agent", ["sac", "td3"])
def test_a_program_without_noisy_runs_skips_the_noise_bit_identically(agent):
    """`noisy_runs=False` builds the actor without its weight-noise draws; for plain runs (noise
    scale 0) the whole training run is bit-identical to the program that draws and zeroes them:
    every eval return, loss, replay entry and weight. Active querying, so the uncertainty u(s) and
    the queries it decides are in the comparison too."""
    cfg = tiny(agent=agent, total_env_steps=600, eval_every=300, learning_starts=100,
               strategy="active", t_query=0.3, budget=80)  # fmt: skip
    hp = hparams_from_config(cfg)
    out = [
        jax.jit(make_train(c, TOY_EXPERT).train)(jax.random.key(4), hp)
        for c in (cfg, cfg.replace(noisy_runs=False))
    ]
    assert int(np.asarray(out[0][0].query.demos_used)) > 0  # queries happened
    raw = lambda x: jax.random.key_data(x) if is_key(x) else x  # noqa: E731
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(raw(a), raw(b)), out[0], out[1])


def test_sweep_program_drops_the_noise_only_when_no_run_is_noisy():
    cfg = tiny()
    intrinsic = Sweep(cfg=cfg, sweep={"strategy": ("none", "active")}, seeds=(0, 1))
    assert intrinsic.program_config() == cfg.replace(noisy_runs=False)
    both = Sweep(cfg=cfg, sweep={"uncertainty": ("intrinsic", "extrinsic")}, seeds=(0,))
    assert both.program_config() == cfg  # one Noisy SAC run keeps the draws for the program
    noisy_base = cfg.replace(uncertainty="extrinsic")
    assert Sweep(cfg=noisy_base).program_config().noisy_runs
    overridden = Sweep(cfg=noisy_base, sweep={"uncertainty": ("intrinsic",)})
    assert overridden.program_config() == cfg.replace(noisy_runs=False)  # every run intrinsic
    boot = cfg.replace(agent="boot_td3")
    assert Sweep(cfg=boot).program_config() == boot  # no noisy head: nothing to drop


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="a CPU lowering")
def test_unrolled_threefry_on_cpu_draws_the_same_bits():
    """`unroll_threefry_on_cpu` (on in every program built with `compiler_options`) changes how the
    generator is lowered, not its numbers: normal, uniform and split draws are bit-equal to JAX's
    own rolled CPU lowering, and the rolled loop is really gone."""
    from jax._src.interpreters import mlir
    from jax._src.random import threefry2x32 as threefry

    def draws(key):
        k1, k2 = jax.random.split(key)
        return (jax.random.normal(k1, (257, 7)), jax.random.uniform(k2, (1000,)),
                jax.random.key_data(jax.random.split(k2, 5)))  # fmt: skip

    def lowered_and_values(key):  # a fresh function each time: a fresh lowering, not a cached one
        fn = jax.jit(lambda k: draws(k))
        return fn.lower(key).as_text(), fn(key)

    key = jax.random.key(7)
    rolled_rule = threefry._threefry2x32_cpu_lowering_rule
    try:
        mlir.register_lowering(threefry.threefry2x32_p, rolled_rule, platform="cpu")
        rolled_text, rolled = lowered_and_values(key)
    finally:
        assert unroll_threefry_on_cpu()
    unrolled_text, unrolled = lowered_and_values(key)
    assert "stablehlo.while" in rolled_text and "stablehlo.while" not in unrolled_text
    jax.tree.map(np.testing.assert_array_equal, rolled, unrolled)
