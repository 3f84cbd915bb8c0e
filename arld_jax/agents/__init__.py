"""The agents, by name. A new agent is one module with `make(cfg, obs_dim, action_dim) -> Agent`
(the interface is `arld_jax.agents.base`) plus one line in `AGENTS`."""

from __future__ import annotations

from collections.abc import Callable

from arld_jax.agents import boot_td3, sac, td3
from arld_jax.agents.base import Acting, Agent, AgentState, UpdateMetrics
from arld_jax.config import AGENT_NAMES, Config

AGENTS: dict[str, Callable[[Config, int, int], Agent]] = {
    "sac": sac.make,
    "td3": td3.make,
    "boot_td3": boot_td3.make,
}
"""Agent family -> its constructor. `Config.agent` names one; `hp.noisy` picks the noisy variant."""

assert set(AGENTS) <= set(AGENT_NAMES), "register the agent's name in config.AGENT_NAMES too"


def make_agent(cfg: Config, obs_dim: int, action_dim: int) -> Agent:
    """The agent named by `cfg.agent`."""
    if cfg.agent not in AGENTS:
        raise ValueError(
            f"Config.agent = {cfg.agent!r} is not built in this version: available "
            + ", ".join(repr(a) for a in AGENTS)
        )
    return AGENTS[cfg.agent](cfg, obs_dim, action_dim)


__all__ = ["AGENTS", "Acting", "Agent", "AgentState", "UpdateMetrics", "make_agent"]
