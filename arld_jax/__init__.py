"""arld_jax: Active Reinforcement Learning from Demonstration (SAC / Noisy SAC) in JAX.

Start at `arld_jax.train.make_train` (the scanned loop), `arld_jax.agents.base` (the agent
interface) and `arld_jax.config.Config`.
"""

__version__ = "0.1.0"
