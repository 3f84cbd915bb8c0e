"""Property-based tests of arld_jax.query: budget, C-step runs, the four strategies, the window.

`query.query_step` is driven by a jitted `lax.scan` over a stream of uncertainties, with episodes of
length L (steps_left = L - t % L). Everything a hypothesis example varies (strategy, b, t_query, C,
budget, L, the streams) is a traced array, so each simulator compiles once per static shape
(num_envs, window size, scan length, window_records) and every example reuses it.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from arld_jax import config, envs, query
from arld_jax.config import HParams

T = 120  # scan length of the general simulations
T_LONG = 400  # scan length of the rate tests
N_SMALL = 10  # reference window that wraps often (not a multiple of 4 envs: wraps mid-step)
N_LARGE = 200  # reference window of the rate tests
BIG_BUDGET = 1_000_000

SETTINGS = settings(max_examples=40, deadline=None)
# Statistical tests run a fixed set of examples so that a rare unlucky draw cannot make them flaky.
STAT_SETTINGS = settings(max_examples=25, deadline=None, derandomize=True)

_BASE_HP = config.hparams_from_config(config.tiny())


def _hp(
    strategy: int, b: float = 0.0, t_query: float = 0.5, c: int = 1, budget: int = 0
) -> HParams:
    return _BASE_HP.replace(
        strategy=jnp.asarray(strategy, jnp.int32),
        query_prob=jnp.asarray(b, jnp.float32),
        t_query=jnp.asarray(t_query, jnp.float32),
        demo_steps=jnp.asarray(c, jnp.int32),
        budget=jnp.asarray(budget, jnp.int32),
    )


_TRACES: dict[tuple[int, str], int] = {}


@functools.cache
def _simulator(window_size: int, window_records: str):  # noqa: ANN202
    """A jitted run of query_step over a [steps, num_envs] uncertainty stream."""

    def run(hp: HParams, key: jax.Array, u: jax.Array, length: jax.Array, n_active: jax.Array):
        _TRACES[(window_size, window_records)] = _TRACES.get((window_size, window_records), 0) + 1
        steps, num_envs = u.shape
        qs0 = query.init_query_state(num_envs, window_size)

        def step(qs, inp):  # noqa: ANN001, ANN202
            t, k, u_t = inp
            steps_left = length - t % length
            allow = t < n_active
            qs, is_demo, new_query = query.query_step(
                qs, k, u_t, steps_left, hp, allow, window_records
            )
            out = (is_demo, new_query, qs.window, qs.window_pos, qs.window_count, qs.demos_used)
            return qs, out

        inputs = (jnp.arange(steps), jax.random.split(key, steps), u)
        final, outs = jax.lax.scan(step, qs0, inputs)
        return final, outs

    return jax.jit(run)


def _simulate(
    hp: HParams,
    u: np.ndarray,
    length: int,
    seed: int = 0,
    window_size: int = N_SMALL,
    window_records: str = "all",
    n_active: int | None = None,
) -> dict[str, np.ndarray]:
    sim = _simulator(window_size, window_records)
    n_active = u.shape[0] if n_active is None else n_active
    final, (is_demo, new_query, window, pos, count, used) = sim(
        hp,
        jax.random.key(seed),
        jnp.asarray(u, jnp.float32),
        jnp.asarray(length, jnp.int32),
        jnp.asarray(n_active, jnp.int32),
    )
    return dict(
        is_demo=np.asarray(is_demo),
        new_query=np.asarray(new_query),
        window=np.asarray(window),
        pos=np.asarray(pos),
        count=np.asarray(count),
        demos_used=np.asarray(used),
        final_used=int(final.demos_used),
        final_remaining=np.asarray(final.demo_remaining),
    )


def _stream(seed: int, steps: int, num_envs: int, ties: bool = False) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = rng.lognormal(size=(steps, num_envs))
    if ties:  # a coarse grid makes many exact ties with the window entries
        u = np.round(u, 1)
    return u.astype(np.float32)


def _check_against_rules(
    u: np.ndarray,
    res: dict[str, np.ndarray],
    *,
    strategy: int,
    t_query: float,
    c: int,
    budget: int,
    length: int,
    window_size: int,
    window_records: str = "all",
    n_active: int | None = None,
) -> None:
    """Replays the documented rules in plain Python and checks every step of the JAX run.

    * a query grants min(C, steps left in the episode, free budget) steps, envs served in order;
    * an env inside a run makes no new query; nothing is queried when not allowed;
    * none never wants, greedy always wants, active wants when the fraction of window values
      strictly above u is below t_query (empty window: never); bernoulli is random (only checked
      for consistency);
    * the window receives every u ('all') or only those of agent-controlled steps ('agent').
    """
    steps, num_envs = u.shape
    n_active = steps if n_active is None else n_active
    is_demo, new_query = res["is_demo"], res["new_query"]
    used = 0
    remaining = np.zeros(num_envs, np.int64)
    history: list[np.float32] = []
    for t in range(steps):
        steps_left = length - t % length
        if t % length == 0:
            assert not np.any(remaining), f"a run crosses the episode boundary at t={t}"
        free = budget - used - int(remaining.sum())
        window = np.asarray(history[-window_size:], np.float32)
        for e in range(num_envs):
            if remaining[e] > 0:
                assert not new_query[t, e], f"env {e} queried inside a run at t={t}"
                continue
            grant = min(c, steps_left, max(free, 0)) if t < n_active else 0
            if strategy == query.NONE:
                want = False
            elif strategy == query.GREEDY:
                want = True
            elif strategy == query.ACTIVE:
                above = np.float32(np.sum(window > u[t, e]))
                want = len(window) > 0 and above / np.float32(len(window)) < np.float32(t_query)
            else:  # bernoulli: random; a query must have been grantable
                want = bool(new_query[t, e])
                assert not want or grant > 0, f"env {e} queried without budget at t={t}"
            assert bool(new_query[t, e]) == (want and grant > 0), (t, e, want, grant)
            if new_query[t, e]:
                remaining[e] = grant
                free -= grant
        expected_demo = remaining > 0
        np.testing.assert_array_equal(is_demo[t], expected_demo, err_msg=f"t={t}")
        used += int(expected_demo.sum())
        remaining -= expected_demo
        assert res["demos_used"][t] == used
        record = np.ones(num_envs, bool) if window_records == "all" else ~expected_demo
        history.extend(u[t][record])
    assert res["final_used"] == used == int(is_demo.sum()) <= budget


# ---------------------------------------------------------------- general invariants

_strategy_ids = st.sampled_from([query.NONE, query.GREEDY, query.BERNOULLI, query.ACTIVE])


@SETTINGS
@given(
    strategy=_strategy_ids,
    b=st.floats(0.0, 1.0),
    t_query=st.floats(0.01, 1.0),
    c=st.integers(1, 12),
    budget=st.integers(0, 300),
    num_envs=st.sampled_from([1, 4]),
    length=st.integers(7, 40),
    window_records=st.sampled_from(["all", "agent"]),
    ties=st.booleans(),
    seed=st.integers(0, 2**31 - 1),
)
def test_query_step_follows_the_rules(
    strategy: int,
    b: float,
    t_query: float,
    c: int,
    budget: int,
    num_envs: int,
    length: int,
    window_records: str,
    ties: bool,
    seed: int,
) -> None:
    """Budget never exceeded and equal to the demonstrated steps; every query starts a run of
    exactly min(C, steps left, free budget) steps that never crosses an episode boundary; no query
    inside a run; none never queries; greedy and active decide exactly by their rules."""
    u = _stream(seed, T, num_envs, ties)
    hp = _hp(strategy, b, t_query, c, budget)
    res = _simulate(hp, u, length, seed, window_records=window_records)
    _check_against_rules(
        u,
        res,
        strategy=strategy,
        t_query=t_query,
        c=c,
        budget=budget,
        length=length,
        window_size=N_SMALL,
        window_records=window_records,
    )
    assert np.all(np.diff(res["demos_used"]) >= 0)
    if strategy == query.NONE:
        assert not res["is_demo"].any()


@SETTINGS
@given(
    strategy=st.sampled_from([query.GREEDY, query.BERNOULLI]),
    c=st.integers(1, 12),
    num_envs=st.sampled_from([1, 4]),
    length=st.integers(7, 40),
    seed=st.integers(0, 2**31 - 1),
)
def test_runs_have_exactly_c_steps_capped_at_the_episode_end(
    strategy: int, c: int, num_envs: int, length: int, seed: int
) -> None:
    """With ample budget every run is min(C, steps left): measured directly on the is_demo runs."""
    u = _stream(seed, T, num_envs)
    res = _simulate(_hp(strategy, 0.3, 0.5, c, BIG_BUDGET), u, length, seed)
    is_demo, new_query = res["is_demo"], res["new_query"]
    for e in range(num_envs):
        starts = np.flatnonzero(new_query[:, e])
        for s in starts:
            run = min(c, length - s % length)
            end = min(s + run, T)  # a run may be cut by the end of the simulation
            assert is_demo[s:end, e].all(), (e, s)
            if end < T:  # the step after the run is not a continuation of it
                assert not is_demo[end, e] or new_query[end, e], (e, s)
        # Every demonstrated step belongs to a run started by a query.
        covered = np.zeros(T, bool)
        for s in starts:
            covered[s : s + min(c, length - s % length)] = True
        np.testing.assert_array_equal(is_demo[:, e], covered)


def test_strategy_none_never_queries() -> None:
    u = _stream(0, T, 4)
    res = _simulate(_hp(query.NONE, b=1.0, t_query=1.0, c=3, budget=BIG_BUDGET), u, 10)
    assert not res["new_query"].any() and not res["is_demo"].any() and res["final_used"] == 0


def test_each_strategy_name_selects_its_rule() -> None:
    """A Config's strategy name reaches `wants_query` as the rule it names. (Every other test here
    passes the ids `query.NONE` ... directly, so this is where a name and an id could disagree.)
    64 envs against a full window of zeros: the first 32 at u = 1 (above every window value, so
    the active rule asks there), the other 32 at u = -1 (it does not); b = 0.5, so the Bernoulli
    rule asks at about half of them anywhere (Binomial(64, 0.5): 32 +- 4; bound 10..54)."""
    qs = query.init_query_state(64, N_SMALL).replace(window_count=jnp.int32(N_SMALL))
    u = jnp.concatenate([jnp.ones(32), -jnp.ones(32)])
    high = np.arange(64) < 32
    want = {}
    for name in config.STRATEGIES:
        hp = config.hparams_from_config(config.tiny(strategy=name, query_prob=0.5, t_query=0.1))
        want[name] = np.asarray(query.wants_query(qs, jax.random.key(0), u, hp))
    assert not want["none"].any()
    assert want["greedy"].all()
    np.testing.assert_array_equal(want["active"], high)
    assert 10 < want["bernoulli"].sum() < 54
    assert want["bernoulli"][~high].any() and not want["bernoulli"][high].all()


def test_simulator_compiles_once_for_all_hparams() -> None:
    """Strategy, b, t_query, C and budget are traced values: changing them never retraces."""
    sim = _simulator(7, "all")  # a window size no other test uses
    u = jnp.asarray(_stream(0, T, 4))
    for strategy, c, budget in ((query.GREEDY, 3, 50), (query.ACTIVE, 1, 9), (query.NONE, 12, 0)):
        sim(_hp(strategy, 0.5, 0.2, c, budget), jax.random.key(0), u, jnp.int32(11), jnp.int32(T))
    assert _TRACES[(7, "all")] == 1


# ---------------------------------------------------------------- greedy


@SETTINGS
@given(
    c=st.integers(1, 12),
    budget=st.integers(0, 300),
    length=st.integers(7, 40),
    seed=st.integers(0, 2**31 - 1),
)
def test_greedy_one_env_spends_the_first_budget_steps(
    c: int, budget: int, length: int, seed: int
) -> None:
    u = _stream(seed, T, 1)
    res = _simulate(_hp(query.GREEDY, c=c, budget=budget), u, length, seed)
    np.testing.assert_array_equal(res["is_demo"][:, 0], np.arange(T) < budget)
    assert res["final_used"] == min(budget, T)


@SETTINGS
@given(
    c=st.integers(1, 12),
    budget=st.integers(0, 600),
    length=st.integers(7, 40),
    seed=st.integers(0, 2**31 - 1),
)
def test_greedy_four_envs_uses_min_budget_total_steps(
    c: int, budget: int, length: int, seed: int
) -> None:
    """Queries are allowed for whole episodes only (so no run is cut by the end of the scan)."""
    n_active = (T // length) * length
    u = _stream(seed, T, 4)
    res = _simulate(_hp(query.GREEDY, c=c, budget=budget), u, length, seed, n_active=n_active)
    total = 4 * n_active
    assert res["final_used"] == int(res["is_demo"].sum()) == min(budget, total)
    assert not res["final_remaining"].any()
    assert not res["is_demo"][n_active:].any()  # no query once they are disallowed


# ---------------------------------------------------------------- query rates


@STAT_SETTINGS
@given(
    b=st.floats(0.02, 0.98),
    c=st.integers(1, 12),
    num_envs=st.sampled_from([1, 4]),
    seed=st.integers(0, 2**31 - 1),
)
def test_bernoulli_rate_among_decision_steps_is_b(
    b: float, c: int, num_envs: int, seed: int
) -> None:
    """Each decision step (no run in progress) queries with probability b: binomial test."""
    u = _stream(seed, T_LONG, num_envs)
    res = _simulate(_hp(query.BERNOULLI, b=b, c=c, budget=BIG_BUDGET), u, 25, seed, N_LARGE)
    new_query, is_demo = res["new_query"], res["is_demo"]
    decisions = int((~is_demo | new_query).sum())  # steps not inside an earlier run
    queries = int(new_query.sum())
    p = stats.binomtest(queries, decisions, b).pvalue
    assert p > 1e-5, (queries, decisions, b)


def test_bernoulli_extremes() -> None:
    u = _stream(0, T, 4)
    never = _simulate(_hp(query.BERNOULLI, b=0.0, c=1, budget=BIG_BUDGET), u, 10)
    always = _simulate(_hp(query.BERNOULLI, b=1.0, c=1, budget=BIG_BUDGET), u, 10)
    assert not never["new_query"].any()
    assert always["new_query"].all() and always["final_used"] == T * 4


@STAT_SETTINGS
@given(
    t_query=st.floats(0.05, 0.7),
    num_envs=st.sampled_from([1, 4]),
    dist=st.sampled_from(["normal", "uniform", "lognormal"]),
    seed=st.integers(0, 2**31 - 1),
)
def test_active_rate_is_t_query_on_a_stationary_stream(
    t_query: float, num_envs: int, dist: str, seed: int
) -> None:
    """On iid continuous uncertainties, once the window of N_r = 200 is full, the active strategy
    queries a fraction ~t_query of the steps (C = 1, unlimited budget)."""
    rng = np.random.default_rng(seed)
    u = getattr(rng, dist)(size=(T_LONG, num_envs)).astype(np.float32)
    res = _simulate(_hp(query.ACTIVE, t_query=t_query, budget=BIG_BUDGET), u, 25, seed, N_LARGE)
    full = -(-N_LARGE // num_envs)  # first step at which the window is full
    assert res["count"][full - 1] == N_LARGE
    decisions = res["new_query"][full:]
    n = decisions.size
    # With K ~ Uniform{0..N} window values above u, P(K/N < t) = ceil(N t) / (N + 1).
    p_exact = np.ceil(N_LARGE * t_query) / (N_LARGE + 1)
    rate = decisions.mean()
    # Binomial sd, widened by the shared window (the threshold fluctuates like a quantile of N
    # values, correlated over N / num_envs steps): 5 binomial sd + 1.5 / sqrt(N).
    tol = 5 * np.sqrt(p_exact * (1 - p_exact) / n) + 1.5 * np.sqrt(
        p_exact * (1 - p_exact) / N_LARGE
    )
    assert abs(rate - p_exact) < tol, (rate, p_exact, tol)
    assert abs(rate - t_query) < tol + 1 / N_LARGE


def test_fraction_above_counts_strictly_greater_valid_entries() -> None:
    # Valid entries (count = 5): [1, 2, 2, 3, 5]; the last two slots are stale and ignored.
    window = jnp.array([1.0, 2.0, 2.0, 3.0, 5.0, 9.0, 9.0])
    count = jnp.int32(5)
    for u, above in ((2.0, 2), (1.0, 4), (0.0, 5), (5.0, 0), (2.5, 2)):
        np.testing.assert_allclose(query.fraction_above(window, count, jnp.float32(u)), above / 5)


@SETTINGS
@given(
    t_query=st.floats(0.01, 1.0),
    c=st.integers(1, 12),
    budget=st.sampled_from([0, 5, 60, 300, BIG_BUDGET]),
    num_envs=st.sampled_from([1, 4]),
    length=st.integers(7, 40),
    window_records=st.sampled_from(["all", "agent"]),
    ties=st.booleans(),
    seed=st.integers(0, 2**31 - 1),
)
def test_active_queries_exactly_when_u_ranks_in_the_top_t_query(
    t_query: float,
    c: int,
    budget: int,
    num_envs: int,
    length: int,
    window_records: str,
    ties: bool,
    seed: int,
) -> None:
    """Every decision of the active strategy, replayed: query iff the fraction of window values
    strictly above u is below t_query (ties do not count as above), budget and runs permitting."""
    u = _stream(seed, T, num_envs, ties)
    res = _simulate(
        _hp(query.ACTIVE, 0.0, t_query, c, budget), u, length, seed, N_SMALL, window_records
    )
    _check_against_rules(
        u,
        res,
        strategy=query.ACTIVE,
        t_query=t_query,
        c=c,
        budget=budget,
        length=length,
        window_size=N_SMALL,
        window_records=window_records,
    )


def test_empty_window_never_queries() -> None:
    u = _stream(0, T, 4)
    res = _simulate(_hp(query.ACTIVE, t_query=1.0, budget=BIG_BUDGET), u, 10)
    assert not res["new_query"][0].any()  # nothing to rank against yet
    assert res["new_query"][1:].any()  # t_query = 1 queries almost everything afterwards


# ---------------------------------------------------------------- reference window


@SETTINGS
@given(
    strategy=st.sampled_from([query.NONE, query.GREEDY, query.BERNOULLI]),
    window_records=st.sampled_from(["all", "agent"]),
    num_envs=st.sampled_from([1, 4]),
    c=st.integers(1, 12),
    budget=st.integers(0, 300),
    seed=st.integers(0, 2**31 - 1),
)
def test_window_ring_holds_the_last_values(
    strategy: int, window_records: str, num_envs: int, c: int, budget: int, seed: int
) -> None:
    """After n insertions the ring holds the last min(n, N_r) values, newest just before window_pos;
    with window_records='agent' demonstrated steps are not inserted."""
    u = _stream(seed, T, num_envs)
    res = _simulate(_hp(strategy, 0.4, 0.5, c, budget), u, 13, seed, N_SMALL, window_records)
    history: list[np.float32] = []
    for t in range(T):
        record = np.ones(num_envs, bool) if window_records == "all" else ~res["is_demo"][t]
        history.extend(u[t][record])
        count, pos, window = int(res["count"][t]), int(res["pos"][t]), res["window"][t]
        assert count == min(len(history), N_SMALL)
        assert pos == len(history) % N_SMALL
        for j in range(count):
            assert window[(pos - 1 - j) % N_SMALL] == history[-1 - j], (t, j)
    if window_records == "agent" and res["is_demo"].any():
        assert len(history) < T * num_envs  # the exclusion was exercised


# ---------------------------------------------------------------- the action mask in training


@pytest.fixture(scope="module")
def toy_run():  # noqa: ANN201
    from arld_jax import expert, train

    cfg = config.tiny(
        strategy="bernoulli",
        query_prob=0.5,
        demo_steps=3,
        budget=60,
        num_envs=2,
        episode_length=20,
        total_env_steps=200,
        eval_every=100,
        learning_starts=100,
        hidden_sizes=(8,),
        batch_size=8,
        replay_capacity=256,  # holds every transition of the run
        num_eval_episodes=1,
        window_size=8,
        state_sample_size=4,
    )
    ex = expert.toy_expert()
    trainer = train.make_train(cfg, ex)
    state, metrics = jax.jit(trainer.train)(jax.random.key(0), config.hparams_from_config(cfg))
    return cfg, state, metrics


def test_training_executes_the_expert_action_exactly_where_is_demo(toy_run) -> None:  # noqa: ANN001
    """Stored transitions hold the executed action: the expert's tanh(W s) on demonstrated steps,
    the agent's (random or sampled) elsewhere, and the budget is spent exactly."""
    cfg, state, metrics = toy_run
    data = state.replay.data
    size = int(state.replay.size)
    assert size == cfg.total_env_steps
    obs, action = np.asarray(data.obs[:size]), np.asarray(data.action[:size])
    is_demo = np.asarray(data.is_demo[:size]) > 0.5
    expert_action = np.asarray(envs.toy_target_action(jnp.asarray(obs)))
    gap = np.max(np.abs(action - expert_action), axis=-1)
    assert 0 < is_demo.sum() == int(metrics.demos_used[-1]) == cfg.budget
    np.testing.assert_allclose(action[is_demo], expert_action[is_demo], atol=1e-6)
    assert np.all(gap[~is_demo] > 1e-4)
