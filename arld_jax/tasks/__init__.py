"""The tasks, by name: every module of this package that declares a `SPEC` (`base.TaskSpec`).

A new task is one module here; nothing else names it. `Config.env_name`'s choices, the default
expert of a task (`TaskSpec.expert_dir`), `envs.make_env` and the per-task tests come from
`REGISTRY`. Importing this package imports neither Brax nor MuJoCo (`arld_jax.physics` does, when a
Brax task is built).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Iterable

from arld_jax.tasks.base import Env, EnvState, TaskSpec, never_upside_down


def discover(package: str = __name__, paths: Iterable[str] = __path__) -> dict[str, TaskSpec]:
    """name -> spec of every module in `paths` that has a `SPEC`, in the order of the modules'
    names."""
    specs: dict[str, TaskSpec] = {}
    for info in sorted(pkgutil.iter_modules(list(paths)), key=lambda m: m.name):
        spec = getattr(importlib.import_module(f"{package}.{info.name}"), "SPEC", None)
        if isinstance(spec, TaskSpec):
            if spec.name in specs:
                raise ValueError(f"two task modules declare the name {spec.name!r}")
            specs[spec.name] = spec
    return specs


REGISTRY: dict[str, TaskSpec] = discover()
"""Task name (`Config.env_name`) -> its spec."""

BRAX_TASKS: tuple[str, ...] = tuple(n for n, s in REGISTRY.items() if s.brax_name is not None)
"""The tasks with physics (Brax's envs), as opposed to the pure-JAX stand-ins of the tests."""

__all__ = ["BRAX_TASKS", "REGISTRY", "Env", "EnvState", "TaskSpec", "never_upside_down"]
