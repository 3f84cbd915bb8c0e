"""Query strategies (paper section 4): when the agent hands control to the expert.

All four strategies run on device, per env, inside the scanned loop, and are selected by an integer
(`hp.strategy`) so that one compiled program can vmap over them:

* none (SAC)         never query.
* greedy (GQSAC)     query at every step until the budget is spent.
* bernoulli (BQSAC)  query with probability b.
* active (AQSAC)     query when the current uncertainty u(s) ranks in the top t_query fraction of a
                     reference window holding the last N_r uncertainties (Chen et al. 2020's
                     proportion-based rule, which the paper reuses with N_r = 5000).

Readings of the paper that are ours (documented in docs/paper_readings.md too):

* Reference window: by default it records the uncertainty of EVERY visited state (agent- or
  expert-controlled; with several envs, all of them), so it describes the agent's recent uncertainty
  distribution independent of how much was queried. `window_records='agent'` records only states where
  the agent was in control. The current values are ranked against the window before they enter it; an
  empty window never triggers a query.
* "u in the top t_query fraction" means: the fraction of window values strictly greater than u is
  below t_query. On a stationary stream this queries at rate ~t_query (tested).
* C-step demonstrations: a query gives the expert control for min(C, steps left in the episode)
  steps (paper A.1: "C consecutive demonstrations ... until the end of the episode"). Envs inside such
  a run make no new decision. A run also ends when its episode ends early, at a fall (`end_episodes`);
  its unused steps return to the budget.
* Budget: counted in demonstrated steps and never exceeded. A query reserves its whole run; when
  several envs query at once, they are granted in env order and the last one may get a shorter run
  (so greedy spends exactly `budget` steps).
"""

from __future__ import annotations

import flax.struct
import jax
import jax.numpy as jnp

from arld_jax.config import STRATEGIES, HParams
from arld_jax.types import PRNGKey

NONE, GREEDY, BERNOULLI, ACTIVE = (
    STRATEGIES.index(name) for name in ("none", "greedy", "bernoulli", "active")
)
"""The strategies' ids on device (`hp.strategy`), each bound by its name."""


@flax.struct.dataclass
class QueryState:
    """Per-run query bookkeeping."""

    demos_used: jax.Array  # i32[]: demonstrated steps so far (budget spent)
    demo_remaining: jax.Array  # i32[num_envs]: steps of the current expert run still to come
    window: jax.Array  # f32[N_r]: ring of recent uncertainties
    window_pos: jax.Array  # i32[]: next ring slot
    window_count: jax.Array  # i32[]: valid entries (<= N_r)


def init_query_state(num_envs: int, window_size: int) -> QueryState:
    """No demonstrations used, no expert in control, an empty reference window."""
    return QueryState(
        demos_used=jnp.zeros((), jnp.int32),
        demo_remaining=jnp.zeros((num_envs,), jnp.int32),
        window=jnp.zeros((window_size,), jnp.float32),
        window_pos=jnp.zeros((), jnp.int32),
        window_count=jnp.zeros((), jnp.int32),
    )


def fraction_above(window: jax.Array, count: jax.Array, u: jax.Array) -> jax.Array:
    """Fraction of the `count` valid window entries strictly greater than the scalar `u`."""
    valid = jnp.arange(window.shape[0]) < count
    above = jnp.sum(valid & (window > u))
    return above / jnp.maximum(count, 1)


def wants_query(qs: QueryState, key: PRNGKey, u: jax.Array, hp: HParams) -> jax.Array:
    """Each env's wish to query this step under strategy `hp.strategy`, before budget and runs. [E]"""
    num_envs = u.shape[0]
    frac = jax.vmap(fraction_above, in_axes=(None, None, 0))(qs.window, qs.window_count, u)
    active = (qs.window_count > 0) & (frac < hp.t_query)
    bernoulli = jax.random.uniform(key, (num_envs,)) < hp.query_prob
    wish = {
        "none": jnp.zeros(num_envs, bool),
        "greedy": jnp.ones(num_envs, bool),
        "bernoulli": bernoulli,
        "active": active,
    }
    return jnp.stack([wish[name] for name in STRATEGIES])[hp.strategy]  # [len(STRATEGIES), E]


def grant(want: jax.Array, qs: QueryState, steps_left: jax.Array, hp: HParams) -> jax.Array:
    """Length of the expert run granted to each env this step (0 = no new query). [E]

    A run lasts min(C, steps left in the episode). The free budget (budget - used - reserved) is
    handed out in env order; it is never exceeded.
    """
    request = jnp.where(want, jnp.minimum(hp.demo_steps, steps_left), 0)
    free = hp.budget - qs.demos_used - jnp.sum(qs.demo_remaining)
    before = jnp.cumsum(request) - request
    return jnp.clip(free - before, 0, request)


def record_uncertainty(qs: QueryState, u: jax.Array, mask: jax.Array) -> QueryState:
    """Append the masked entries of `u` to the reference window ring."""
    size = qs.window.shape[0]
    offset = jnp.cumsum(mask) - 1
    slots = jnp.where(
        mask, (qs.window_pos + offset) % size, size
    )  # `size` is out of range: dropped
    window = qs.window.at[slots].set(u, mode="drop")
    n = jnp.sum(mask).astype(jnp.int32)
    return qs.replace(
        window=window,
        window_pos=(qs.window_pos + n) % size,
        window_count=jnp.minimum(qs.window_count + n, size),
    )


def query_step(
    qs: QueryState,
    key: PRNGKey,
    u: jax.Array,
    steps_left: jax.Array,
    hp: HParams,
    allow: jax.Array | bool = True,
    window_records: str = "all",
) -> tuple[QueryState, jax.Array, jax.Array]:
    """Decide, for each env, whether the expert acts at this step.

    u: [E] the agent's uncertainty at the current states. steps_left: scalar or [E], steps left in the
    episode including this one. allow: whether new queries may start (e.g. not during warm-up).
    Returns (new state, is_demo [E] bool: the expert acts now, new_query [E] bool: a run starts now).
    """
    in_run = qs.demo_remaining > 0
    want = wants_query(qs, key, u, hp) & ~in_run & allow
    granted = grant(want, qs, jnp.broadcast_to(steps_left, u.shape), hp)
    remaining = qs.demo_remaining + granted
    is_demo = remaining > 0
    qs = qs.replace(
        demos_used=qs.demos_used + jnp.sum(is_demo).astype(jnp.int32),
        demo_remaining=remaining - is_demo.astype(jnp.int32),
    )
    record = jnp.ones_like(is_demo) if window_records == "all" else ~is_demo
    qs = record_uncertainty(qs, u, record)
    return qs, is_demo, granted > 0


def hand_back(
    qs: QueryState, is_demo: jax.Array, declined: jax.Array
) -> tuple[QueryState, jax.Array]:
    """An expert hands a query back (a person pressing "hand back" at the demonstration page):
    where `declined` [E], this step is the agent's, the rest of the run is cancelled and its budget
    returned. Returns the state and the steps the expert really acts on [E]."""
    qs = qs.replace(
        demos_used=qs.demos_used - jnp.sum(declined).astype(jnp.int32),
        demo_remaining=jnp.where(declined, 0, qs.demo_remaining),
    )
    return qs, is_demo & ~declined


def end_episodes(qs: QueryState, done: jax.Array) -> QueryState:
    """Envs whose episode ended (`done` [E]: a fall or the time limit) leave any expert run: a C-step
    demonstration ends with its episode (paper A.1, "until the end of the episode"), and the steps it
    had reserved but not used return to the budget (`demos_used` counts executed steps only)."""
    return qs.replace(demo_remaining=jnp.where(done, 0, qs.demo_remaining))
