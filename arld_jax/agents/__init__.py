"""The agents, by name: every module of this package that declares a `SPEC` (`base.AgentSpec`).

A new agent is one module here with `make(cfg, obs_dim, action_dim) -> Agent` (the interface is
`arld_jax.agents.base`) and its `SPEC`; nothing else names it. `Config.agent`'s choices, its own
Config fields and checks, the names in summaries and figures, expert export and the contract tests
(`tests/test_td3.py`) all come from `REGISTRY`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from arld_jax.agents.base import Acting, Agent, AgentSpec, AgentState, UpdateMetrics
from arld_jax.registry import discover

if TYPE_CHECKING:
    from arld_jax.config import Config


REGISTRY: dict[str, AgentSpec] = discover(__name__, __path__, AgentSpec)
"""Agent family -> its spec. `Config.agent` names one; `hp.noisy` picks the noisy variant."""


def make_agent(cfg: Config, obs_dim: int, action_dim: int) -> Agent:
    """The agent named by `cfg.agent` (validated by Config against `REGISTRY`)."""
    return REGISTRY[cfg.agent].make(cfg, obs_dim, action_dim)


__all__ = ["REGISTRY", "Acting", "Agent", "AgentSpec", "AgentState", "UpdateMetrics", "make_agent"]
