"""Expert save / load: round trip, deterministic acting, clear errors for missing or misfit experts."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from arld_jax.expert import load_expert, save_expert
from arld_jax.networks import Actor, deterministic_action


def _actor_and_params(obs_dim=4, action_dim=2, hidden=(8, 8)):
    actor = Actor(action_dim=action_dim, hidden_sizes=hidden)
    params = actor.init(jax.random.key(1), jnp.zeros((1, obs_dim)), jax.random.key(2), 0.0)
    meta = dict(obs_dim=obs_dim, action_dim=action_dim, hidden_sizes=list(hidden), env_name="toy")
    return actor, params, meta


def test_round_trip_acts_like_the_saved_actor(tmp_path):
    actor, params, meta = _actor_and_params()
    save_expert(tmp_path / "e", params, meta | {"eval_return": 12.5})
    expert = load_expert(tmp_path / "e", obs_dim=4, action_dim=2)
    obs = jax.random.normal(jax.random.key(3), (5, 4))
    want = deterministic_action(actor.apply(params, obs, jax.random.key(0), 0.0))
    got = expert.act(expert.params, obs, jax.random.key(7))
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), atol=1e-6)
    # Deterministic: the key does not matter.
    np.testing.assert_array_equal(
        np.asarray(got), np.asarray(expert.act(expert.params, obs, jax.random.key(8)))
    )
    assert expert.meta["eval_return"] == 12.5
    stochastic = load_expert(tmp_path / "e", obs_dim=4, action_dim=2, stochastic=True)
    a1 = stochastic.act(stochastic.params, obs, jax.random.key(7))
    assert not np.allclose(np.asarray(a1), np.asarray(got))


def test_missing_expert_says_how_to_get_one(tmp_path):
    with pytest.raises(FileNotFoundError, match="train_expert"):
        load_expert(tmp_path / "nowhere", obs_dim=4, action_dim=2)


def test_expert_for_another_env_is_refused(tmp_path):
    _, params, meta = _actor_and_params()
    save_expert(tmp_path / "e", params, meta)
    with pytest.raises(ValueError, match="obs_dim=4, action_dim=2"):
        load_expert(tmp_path / "e", obs_dim=17, action_dim=6)


def test_parameters_that_do_not_match_the_metadata_are_refused(tmp_path):
    _, params, meta = _actor_and_params(hidden=(8, 8))
    save_expert(tmp_path / "e", params, meta)
    meta_file = tmp_path / "e" / "expert.json"
    meta_file.write_text(json.dumps(meta | {"hidden_sizes": [16, 8]}))
    with pytest.raises(ValueError, match="does not match"):
        load_expert(tmp_path / "e", obs_dim=4, action_dim=2)
