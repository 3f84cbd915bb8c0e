"""The gait metric (upside-down torso) on constructed HalfCheetah observations."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from arld_jax import envs, gait

OBS_DIM = 17  # Brax halfcheetah


def _obs_with_pitch(pitches: list[float]) -> np.ndarray:
    obs = np.random.default_rng(0).normal(size=(len(pitches), OBS_DIM))
    obs[:, gait.HALFCHEETAH_PITCH_INDEX] = pitches
    return obs


# pitch (radians, as MuJoCo's unbounded hinge reports it) -> upside down?
CASES = [
    (0.0, False),
    (1.5, False),  # 86 degrees: steep but upright
    (-1.5, False),
    (1.65, True),  # 94.5 degrees
    (-1.65, True),
    (np.pi, True),  # on its back
    (2 * np.pi + 0.2, False),  # a full flip and back upright: the wrap matters
    (-2 * np.pi - 0.2, False),
    (3 * np.pi, True),
    (-4.0, True),  # -229 deg = +131 deg
]


@pytest.mark.parametrize("xp", [np, jnp], ids=["numpy", "jax"])
def test_upside_down_on_constructed_pitches(xp) -> None:  # noqa: ANN001
    pitches, expected = zip(*CASES, strict=True)
    obs = _obs_with_pitch(list(pitches))
    got = np.asarray(gait.upside_down(xp.asarray(obs), xp))
    np.testing.assert_array_equal(got, expected)


def test_only_the_pitch_matters() -> None:
    """Other observation entries (height, joint angles, velocities) do not change the verdict."""
    obs = _obs_with_pitch([0.3, 2.5])
    other = obs.copy()
    other[:, [0, 2, 3, 10]] = 50.0
    np.testing.assert_array_equal(gait.upside_down(obs), gait.upside_down(other))
    np.testing.assert_array_equal(gait.upside_down(obs), [False, True])


def test_env_layer_uses_it_and_keeps_batch_shape() -> None:
    obs = _obs_with_pitch([0.0, np.pi, 0.1, -3.0, 1.0, 2.0]).reshape(2, 3, OBS_DIM)
    got = envs.halfcheetah_upside_down(jnp.asarray(obs))
    assert got.shape == (2, 3)
    np.testing.assert_array_equal(got, [[False, True, False], [True, False, True]])
    assert not np.any(envs.never_upside_down(jnp.asarray(obs)))
