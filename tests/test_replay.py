"""Tests for arld_jax.replay (proportional prioritized replay, Schaul et al. 2015)."""

from __future__ import annotations

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from arld_jax.replay import (
    make_prioritized_replay,
    priority_from_td,
    replay_nbytes,
)

OBS_DIM = 3
ACTION_DIM = 2


@flax.struct.dataclass
class _Item:
    """Stand-in with the same layout as the project's Transition (replay is generic)."""

    obs: jax.Array
    action: jax.Array
    reward: jax.Array
    next_obs: jax.Array
    terminated: jax.Array
    is_demo: jax.Array


def _example_item(obs_dim: int = OBS_DIM, action_dim: int = ACTION_DIM) -> _Item:
    return _Item(
        obs=jnp.zeros((obs_dim,), jnp.float32),
        action=jnp.zeros((action_dim,), jnp.float32),
        reward=jnp.zeros((), jnp.float32),
        next_obs=jnp.zeros((obs_dim,), jnp.float32),
        terminated=jnp.zeros((), jnp.float32),
        is_demo=jnp.zeros((), jnp.float32),
    )


def _items(values: np.ndarray) -> _Item:
    """A batch of items whose every field is filled with the given per-item value."""
    v = jnp.asarray(values, jnp.float32)
    n = v.shape[0]
    return _Item(
        obs=jnp.broadcast_to(v[:, None], (n, OBS_DIM)),
        action=jnp.broadcast_to(v[:, None], (n, ACTION_DIM)),
        reward=v,
        next_obs=jnp.broadcast_to(v[:, None] + 0.5, (n, OBS_DIM)),
        terminated=jnp.zeros_like(v),
        is_demo=(v % 2 == 0).astype(jnp.float32),
    )


def _num_leaves(tree: jax.Array) -> int:
    return tree.shape[0] // 2


def _leaves(state, capacity: int) -> np.ndarray:
    tree = np.asarray(state.tree)
    p = _num_leaves(tree)
    return tree[p : p + capacity]


def _full_buffer(capacity: int, batch_size: int, alpha: float, priorities: np.ndarray):
    replay = make_prioritized_replay(capacity, batch_size, alpha)
    state = replay.init(_example_item())
    state = replay.add(state, _items(np.arange(capacity)))
    state = replay.set_priorities(
        state, jnp.arange(capacity, dtype=jnp.int32), jnp.asarray(priorities, jnp.float32)
    )
    return replay, state


# 1. Sampling frequencies follow p**alpha / sum (Schaul eq. 1).
@pytest.mark.parametrize("alpha", [0.0, 0.6, 1.0])
def test_sampling_frequencies_match_priorities(alpha: float) -> None:
    # batch_size <= capacity is required, so take many calls of a small batch (16_000 draws).
    capacity, batch_size, n_calls = 10, 8, 2000
    priorities = np.arange(1.0, capacity + 1.0)  # distinct raw priorities 1..10
    replay, state = _full_buffer(capacity, batch_size, alpha, priorities)

    keys = jax.random.split(jax.random.key(0), n_calls)
    sample_many = jax.jit(jax.vmap(replay.sample, in_axes=(None, 0, None)))
    items, indices, _ = sample_many(state, keys, 0.4)
    indices = np.asarray(indices).ravel()
    # The items returned are the ones stored at the returned indices.
    np.testing.assert_array_equal(np.asarray(items.reward).ravel(), indices.astype(np.float32))

    counts = np.bincount(indices, minlength=capacity)
    assert counts.shape == (capacity,)
    n = indices.size

    expected = priorities**alpha / np.sum(priorities**alpha)
    assert stats.chisquare(counts, n * expected).pvalue > 1e-3
    if alpha == 0.0:
        np.testing.assert_allclose(expected, np.full(capacity, 1 / capacity))

    # Power check: the same counts must reject a clearly different distribution, so the
    # assertion above is not vacuous.
    wrong_alpha = 1.0 if alpha != 1.0 else 0.5
    wrong = priorities**wrong_alpha / np.sum(priorities**wrong_alpha)
    assert stats.chisquare(counts, n * wrong).pvalue < 1e-3


# 2. Importance-sampling weights against hand-computed values.
def test_importance_weights_hand_computed() -> None:
    # capacity 4, batch 2, alpha 1, three items with raw priorities [1, 1, 2]:
    #   leaves = [1, 1, 2, 0], total = 4, P = [0.25, 0.25, 0.5], N = size = 3.
    # Stratified segments are [0, 2) and [2, 4); the cumulative ranges are item0 [0, 1),
    # item1 [1, 2), item2 [2, 4), so sample 0 is item 0 or 1 and sample 1 is always item 2.
    #   unnormalised w = (N * P)^-beta: item0/1 -> 0.75^-beta, item2 -> 1.5^-beta
    #   batch max is 0.75^-beta, so normalised w = [1, (1.5 / 0.75)^-beta] = [1, 2^-beta]
    #   beta = 0.5 -> [1, 0.70710678]; beta = 1 -> [1, 0.5]; beta = 0 -> [1, 1].
    replay = make_prioritized_replay(capacity=4, batch_size=2, alpha=1.0)
    state = replay.init(_example_item())
    state = replay.add(state, _items(np.arange(3)))
    state = replay.set_priorities(state, jnp.arange(3), jnp.array([1.0, 1.0, 2.0]))
    np.testing.assert_allclose(_leaves(state, 4), [1.0, 1.0, 2.0, 0.0])

    sample = jax.jit(replay.sample)
    for beta, w1 in [(0.5, np.sqrt(0.5)), (1.0, 0.5), (0.0, 1.0)]:
        for seed in range(10):
            _, idx, w = sample(state, jax.random.key(seed), jnp.float32(beta))
            idx, w = np.asarray(idx), np.asarray(w)
            assert idx[0] in (0, 1) and idx[1] == 2
            assert w.dtype == np.float32
            np.testing.assert_allclose(w, [1.0, w1], rtol=1e-6)


# 3. Ring insertion wraps around and overwrites the oldest items at the max priority.
def test_ring_wraparound() -> None:
    alpha = 0.5
    replay = make_prioritized_replay(capacity=5, batch_size=2, alpha=alpha)
    state = replay.init(_example_item())
    assert int(state.size) == 0 and int(state.insert_pos) == 0
    assert float(state.max_priority) == 1.0

    state = replay.add(state, _items(np.array([0.0, 1.0, 2.0])))
    assert int(state.insert_pos) == 3 and int(state.size) == 3
    # New items get max_priority (1.0) ** alpha; empty and padding leaves stay 0.
    np.testing.assert_allclose(np.asarray(state.tree)[8:], [1, 1, 1, 0, 0, 0, 0, 0])

    # Raise the running max to 9 via item 0 and lower item 2.
    state = replay.set_priorities(state, jnp.array([0, 2]), jnp.array([9.0, 0.25]))
    assert float(state.max_priority) == 9.0
    np.testing.assert_allclose(_leaves(state, 5), [3.0, 1.0, 0.5, 0.0, 0.0])

    state = jax.jit(replay.add)(state, _items(np.array([3.0, 4.0, 5.0, 6.0])))
    # Positions (3 + arange(4)) % 5 = [3, 4, 0, 1]: items 0 and 1 (the oldest) are overwritten.
    np.testing.assert_array_equal(np.asarray(state.data.reward), [5.0, 6.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(np.asarray(state.data.obs[:, 0]), [5.0, 6.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(np.asarray(state.data.next_obs[:, 1]), [5.5, 6.5, 2.5, 3.5, 4.5])
    assert int(state.insert_pos) == 2
    assert int(state.size) == 5
    # The four new items sit at max_priority ** alpha = 3; item 2 keeps its 0.25 ** 0.5.
    np.testing.assert_allclose(_leaves(state, 5), [3.0, 3.0, 0.5, 3.0, 3.0])
    np.testing.assert_allclose(float(state.tree[1]), 12.5)
    assert float(state.max_priority) == 9.0

    # Adding more than capacity items at once is rejected statically.
    with pytest.raises(ValueError, match="capacity"):
        replay.add(state, _items(np.arange(6)))


def _assert_tree_consistent(tree: np.ndarray) -> None:
    p = _num_leaves(tree)
    for j in range(1, p):
        # Exact: each parent is recomputed as the f32 sum of its two children.
        assert tree[j] == np.float32(tree[2 * j] + tree[2 * j + 1]), j


# 4. set_priorities keeps the sum tree exact, with duplicate indices; max_priority tracks max.
def test_set_priorities_sum_tree_exact() -> None:
    capacity, alpha = 13, 0.7  # P = 16, three padding leaves
    replay = make_prioritized_replay(capacity, batch_size=4, alpha=alpha)
    state = replay.init(_example_item())
    state = replay.add(state, _items(np.arange(capacity)))
    set_priorities = jax.jit(replay.set_priorities)
    rng = np.random.default_rng(0)
    running_max = 1.0
    for _ in range(6):
        before = _leaves(state, capacity).copy()
        idx = rng.integers(0, capacity, size=20)
        idx[1] = idx[0]  # guarantee a duplicate
        pri = rng.uniform(0.1, 5.0, size=20).astype(np.float32)
        state = set_priorities(state, jnp.asarray(idx, jnp.int32), jnp.asarray(pri))
        tree = np.asarray(state.tree)

        _assert_tree_consistent(tree)
        leaves = tree[16 : 16 + capacity]
        np.testing.assert_allclose(tree[1], leaves.sum(), rtol=1e-5)
        np.testing.assert_array_equal(tree[16 + capacity :], 0.0)
        for i in range(capacity):
            written = pri[idx == i] ** alpha
            if written.size == 0:
                assert leaves[i] == before[i]  # untouched leaves are unchanged
            else:
                # With duplicates one of the written values wins.
                assert np.min(np.abs(written - leaves[i]) / written) < 1e-5
        running_max = max(running_max, float(pri.max()))
        np.testing.assert_allclose(float(state.max_priority), running_max, rtol=1e-7)


# 5. Sampling never returns an index >= size (partial buffer, capacity not a power of two).
def test_sample_never_returns_invalid_index() -> None:
    capacity, size, batch_size = 12, 5, 8
    replay = make_prioritized_replay(capacity, batch_size, alpha=1.0)
    state0 = replay.init(_example_item())
    state0 = replay.add(state0, _items(np.arange(size)))
    sample_many = jax.jit(jax.vmap(replay.sample, in_axes=(None, 0, None)))
    keys = jax.random.split(jax.random.key(1), 300)
    configs = [
        np.ones(size),
        np.array([1.0, 1.0, 1.0, 1.0, 1e6]),  # the last valid leaf takes almost all mass
        np.array([1e6, 1e6, 1e6, 1e6, 1e-6]),  # the last valid leaf is nearly empty
        np.random.default_rng(2).uniform(0.01, 10.0, size),
    ]
    for pri in configs:
        state = replay.set_priorities(state0, jnp.arange(size), jnp.asarray(pri, jnp.float32))
        _, idx, w = sample_many(state, keys, 1.0)
        idx, w = np.asarray(idx), np.asarray(w)
        assert idx.min() >= 0 and idx.max() < size, pri
        assert np.all(np.isfinite(w)) and np.all(w > 0) and np.all(w <= 1.0)
        np.testing.assert_allclose(w.max(axis=1), 1.0)
    # Freshly added items all share max priority, so all valid indices get sampled.
    _, idx, _ = sample_many(state0, keys, 1.0)
    assert set(np.unique(np.asarray(idx))) == set(range(size))

    # Exaggerated round-off: inflate the root by 10% so that the top stratum's draws exceed the
    # true sum of the leaves. A naive descent would then walk into the empty right subtree
    # (leaves >= size); the guards must still return the last valid index.
    state = replay.set_priorities(state0, jnp.arange(size), jnp.ones(size))
    state = state.replace(tree=state.tree.at[1].multiply(1.1))
    _, idx, _ = sample_many(state, keys, 1.0)
    idx = np.asarray(idx)
    assert idx.min() >= 0 and idx.max() < size
    assert np.mean(idx[:, -1] == size - 1) > 0.5  # the overflow went to the last valid item


# 6. priority_from_td: p = delta**2 + eps + eps_demo * is_demo.
def test_priority_from_td_adds_eps_demo() -> None:
    td = jnp.array([0.5, 0.5, -2.0, 0.0])
    is_demo = jnp.array([0.0, 1.0, 1.0, 0.0])
    # 0.25 + 0.25 = 0.5; 0.25 + 0.25 + 1 = 1.5; 4 + 0.25 + 1 = 5.25; 0 + 0.25 = 0.25.
    p = priority_from_td(td, is_demo, eps=0.25, eps_demo=1.0)
    np.testing.assert_array_equal(np.asarray(p), [0.5, 1.5, 5.25, 0.25])

    rng = np.random.default_rng(0)
    td = jnp.asarray(rng.normal(size=50), jnp.float32)
    eps, eps_demo = jnp.float32(1e-3), jnp.float32(0.7)
    p_demo = priority_from_td(td, jnp.ones(50), eps, eps_demo)
    p_agent = priority_from_td(td, jnp.zeros(50), eps, eps_demo)
    np.testing.assert_allclose(np.asarray(p_agent), np.asarray(td) ** 2 + 1e-3, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(p_demo - p_agent), 0.7, rtol=1e-5)


# 7. Invalid arguments raise ValueError naming the argument.
@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"capacity": 0, "batch_size": 1}, "capacity"),
        ({"capacity": -3, "batch_size": 1}, "capacity"),
        ({"capacity": 4, "batch_size": 0}, "batch_size"),
        ({"capacity": 4, "batch_size": 5}, "batch_size"),
        ({"capacity": 4, "batch_size": 2, "alpha": -0.1}, "alpha"),
    ],
)
def test_invalid_arguments(kwargs: dict, name: str) -> None:
    value = kwargs[name] if name in kwargs else kwargs["alpha"]
    with pytest.raises(ValueError, match=rf"{name}.*{value}"):
        make_prioritized_replay(**kwargs)


# 8. vmap over three independent buffers equals running each one alone.
def test_vmap_matches_individual_runs() -> None:
    replay = make_prioritized_replay(capacity=7, batch_size=4, alpha=0.6)
    n_seeds, n_steps, n_add = 3, 4, 3

    def step(state, items, key, beta):
        state = replay.add(state, items)
        batch, idx, w = replay.sample(state, key, beta)
        td = batch.reward - 0.3 * batch.obs[:, 0] + w
        state = replay.set_priorities(state, idx, priority_from_td(td, batch.is_demo, 1e-3, 0.5))
        return state, (batch, idx, w)

    rng = np.random.default_rng(3)
    all_items = [[_items(rng.normal(size=n_add)) for _ in range(n_steps)] for _ in range(n_seeds)]
    keys = jax.random.split(jax.random.key(4), (n_seeds, n_steps))
    betas = jnp.array([0.4, 0.7, 1.0])

    single = jax.jit(step)
    expected = []
    for s in range(n_seeds):
        state = replay.init(_example_item())
        outs = []
        for t in range(n_steps):
            state, out = single(state, all_items[s][t], keys[s, t], betas[s])
            outs.append(out)
        expected.append((state, outs))

    batched = jax.jit(jax.vmap(step))
    state = jax.vmap(lambda _: replay.init(_example_item()))(jnp.arange(n_seeds))
    for t in range(n_steps):
        items_t = jax.tree.map(lambda *xs: jnp.stack(xs), *[all_items[s][t] for s in range(3)])
        state, out = batched(state, items_t, keys[:, t], betas)
        for s in range(n_seeds):
            got = jax.tree.map(lambda x, s=s: x[s], out)
            np.testing.assert_array_equal(np.asarray(got[1]), np.asarray(expected[s][1][t][1]))
            jax.tree.map(
                lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6),
                got,
                expected[s][1][t],
            )
    for s in range(n_seeds):
        jax.tree.map(
            lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6),
            jax.tree.map(lambda x, s=s: x[s], state),
            expected[s][0],
        )
    # The three buffers really are different (different data and keys).
    assert not np.array_equal(np.asarray(state.tree[0]), np.asarray(state.tree[1]))


# 9. A jitted sample + set_priorities step traces once across calls with new keys/values.
def test_jitted_step_traces_once() -> None:
    replay, state = _full_buffer(8, 4, 0.6, np.arange(1.0, 9.0))
    n_traces = [0]

    @jax.jit
    def step(state, key, beta, scale):
        n_traces[0] += 1  # Python side effect: runs only while tracing
        _, idx, w = replay.sample(state, key, beta)
        return replay.set_priorities(state, idx, scale * w + 0.1)

    trees = []
    for i in range(5):
        state = step(state, jax.random.key(i), jnp.float32(0.4 + 0.1 * i), jnp.float32(i + 1))
        trees.append(np.asarray(state.tree))
    assert n_traces[0] == 1
    assert not np.array_equal(trees[0], trees[-1])
    _assert_tree_consistent(trees[-1])


def test_replay_nbytes() -> None:
    replay = make_prioritized_replay(capacity=1000, batch_size=32)
    state = replay.init(_example_item(obs_dim=17, action_dim=6))
    # data: 1000 * (17 + 6 + 1 + 17 + 1 + 1) f32 = 172_000 bytes; tree: 2 * 1024 f32 = 8192;
    # max_priority, insert_pos, size: 3 * 4 bytes.
    assert replay_nbytes(state) == 172_000 + 8192 + 12
