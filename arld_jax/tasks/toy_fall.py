"""toy_fall: the `toy` task with a fall, the tests' stand-in for Hopper's health rule.

A step whose squared action error e (see `toy`) exceeds `TOY_FALL_ERROR` terminates the episode:
a uniform-random policy falls after about 26 steps on average, the target policy never.
"""

from __future__ import annotations

import functools

from arld_jax.tasks.base import TaskSpec
from arld_jax.tasks.toy import toy_env, toy_target_action

TOY_FALL_ERROR = 1.8
"""`toy_fall` ends an episode (a "fall") when the squared action error exceeds this."""

SPEC = TaskSpec(
    name="toy_fall",
    summary="the toy task with a fall: ends when the action strays far from the target",
    can_terminate=True,
    make_pure=functools.partial(toy_env, fall_error=TOY_FALL_ERROR),
    target_action=toy_target_action,
)
