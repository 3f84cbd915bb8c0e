"""The agents, by name: every module of this package that declares a `SPEC` (`base.AgentSpec`).

A new agent is one module here with `make(cfg, obs_dim, action_dim) -> Agent` (the interface is
`arld_jax.agents.base`) and its `SPEC`; nothing else names it. `Config.agent`'s choices, its own
Config fields and checks, the names in summaries and figures, expert export and the contract tests
(`tests/test_td3.py`) all come from `REGISTRY`.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Iterable
from typing import TYPE_CHECKING

from arld_jax.agents.base import Acting, Agent, AgentSpec, AgentState, UpdateMetrics

if TYPE_CHECKING:
    from arld_jax.config import Config


def discover(package: str = __name__, paths: Iterable[str] = __path__) -> dict[str, AgentSpec]:
    """name -> spec of every module in `paths` (the package's folders) that has a `SPEC`, in the
    order of the modules' names."""
    specs: dict[str, AgentSpec] = {}
    for info in sorted(pkgutil.iter_modules(list(paths)), key=lambda m: m.name):
        spec = getattr(importlib.import_module(f"{package}.{info.name}"), "SPEC", None)
        if isinstance(spec, AgentSpec):
            if spec.name in specs:
                raise ValueError(f"two agent modules declare the name {spec.name!r}")
            specs[spec.name] = spec
    return specs


REGISTRY: dict[str, AgentSpec] = discover()
"""Agent family -> its spec. `Config.agent` names one; `hp.noisy` picks the noisy variant."""


def make_agent(cfg: Config, obs_dim: int, action_dim: int) -> Agent:
    """The agent named by `cfg.agent` (validated by Config against `REGISTRY`)."""
    return REGISTRY[cfg.agent].make(cfg, obs_dim, action_dim)


__all__ = ["REGISTRY", "Acting", "Agent", "AgentSpec", "AgentState", "UpdateMetrics", "make_agent"]
