"""The tasks, by name: every module of this package that declares a `SPEC` (`base.TaskSpec`).

A new task is one module here; nothing else names it. `Config.env_name`'s choices, the default
expert of a task (`TaskSpec.expert_dir`), `envs.make_env` and the per-task tests come from
`REGISTRY`. Importing this package imports neither Brax nor MuJoCo (`arld_jax.physics` does, when a
Brax task is built).
"""

from __future__ import annotations

from arld_jax.registry import discover
from arld_jax.tasks.base import Env, EnvState, TaskSpec, never_upside_down

REGISTRY: dict[str, TaskSpec] = discover(__name__, __path__, TaskSpec)
"""Task name (`Config.env_name`) -> its spec."""

BRAX_TASKS: tuple[str, ...] = tuple(n for n, s in REGISTRY.items() if s.brax_name is not None)
"""The tasks with physics (Brax's envs), as opposed to the pure-JAX stand-ins of the tests."""

__all__ = ["BRAX_TASKS", "REGISTRY", "Env", "EnvState", "TaskSpec", "never_upside_down"]
