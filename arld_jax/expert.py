"""The expert: a pre-trained SAC actor, saved with orbax-checkpoint beside a small JSON of metadata.

The paper's expert is "a pre-trained prioritized SAC model" (A.1). `python -m arld_jax.run
train_expert` trains one with this package's own trainer (strategy 'none') and saves the actor only.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import flax.struct
import jax
import jax.numpy as jnp

from arld_jax.networks import Actor, deterministic_action, sample_action
from arld_jax.types import Params, PRNGKey

META_FILE = "expert.json"
PARAMS_DIR = "actor"


@flax.struct.dataclass
class ExpertContext:
    """What the loop knows when it asks the expert, for experts that look beyond the state (a
    person at the demonstration page, arld_jax.human). All per env [n] unless noted."""

    agent_action: jax.Array  # [n, A] the action the agent proposes
    uncertainty: jax.Array  # u(s) of the agent
    is_demo: jax.Array  # bool: the expert acts in this env at this step
    new_query: bool | jax.Array  # bool: a query (a run of C demonstrated steps) starts here
    demo_remaining: jax.Array  # i32: demonstrated steps of the current run still to come after this
    demos_used: jax.Array  # i32[]: budget spent, this step included
    budget: jax.Array  # i32[]: the run's demonstration budget
    env_step: jax.Array  # i32[]: env steps done before this step


class Expert(NamedTuple):
    """Expert parameters and an acting function act(params, obs [n, d], key, context) -> action
    [n, A]. A saved policy ignores the context; the loop calls `act` only at iterations where
    some env of the run is demonstrated (a `lax.cond`), so an expert may be slow or a person.

    A row of NaNs from `act` hands that env's query back to the agent: the step is the agent's
    (not a demonstration), the rest of the query is cancelled and its budget is not spent.
    `observe(obs, next_obs, fell, context)`, if set, sees every iteration after its env step: the
    states acted in, the states reached (true next observations, before any reset) and which envs
    fell there, ending their episodes (a person's page shows the states before a query and each
    fall; `arld_jax.human`). It must be an ordered host callback, so such an expert runs one run at
    a time (no vmap)."""

    params: Params
    act: Callable[[Params, jax.Array, PRNGKey, ExpertContext | None], jax.Array]
    meta: dict[str, Any]
    observe: Callable[[jax.Array, jax.Array, jax.Array, ExpertContext], Any] | None = None


def toy_expert() -> Expert:
    """The toy tasks' optimal policy, known in closed form: the expert of tests and tiny runs."""
    from arld_jax.tasks.toy import toy_target_action

    return Expert(
        params={},
        act=lambda p, obs, key, context=None: toy_target_action(obs),
        meta={"name": "toy"},
    )


def expert_from_actor(
    actor: Actor, params: Params, meta: dict[str, Any], stochastic: bool = False
) -> Expert:
    """Wrap a trained actor. The expert acts with tanh(mu) unless `stochastic`."""

    def act(
        p: Params, obs: jax.Array, key: PRNGKey, context: ExpertContext | None = None
    ) -> jax.Array:
        k_noise, k_sample = jax.random.split(key)
        pol = actor.apply(p, obs, k_noise, jnp.float32(0.0))
        return sample_action(pol, k_sample)[0] if stochastic else deterministic_action(pol)

    return Expert(params=params, act=act, meta=meta)


def save_expert(path: str | Path, actor_params: Params, meta: dict[str, Any]) -> Path:
    """Save actor parameters (orbax) and `meta` (JSON: dims, hidden sizes, return, seed, command)."""
    import orbax.checkpoint as ocp

    path = Path(path).absolute()
    path.mkdir(parents=True, exist_ok=True)
    ckpt = ocp.StandardCheckpointer()
    ckpt.save(path / PARAMS_DIR, actor_params, force=True)
    ckpt.wait_until_finished()
    (path / META_FILE).write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    return path


def train_expert_command(env_name: str) -> str:
    """The command that trains task `env_name`'s expert (plain SAC, 5 seeds of 300k env steps, the
    `sac_300k` preset) and saves the best seed's actor where the task's runs find it."""
    return f"python -m arld_jax.run train_expert --preset sac_300k --env_name {env_name}"


def read_expert_meta(path: str | Path) -> dict[str, Any]:
    """The expert's metadata; FileNotFoundError (saying how to get one) if no expert is there."""
    path = Path(path).absolute()
    meta_file = path / META_FILE
    if not meta_file.is_file() or not (path / PARAMS_DIR).is_dir():
        raise FileNotFoundError(
            f"No expert at {path}: expected {META_FILE} and {PARAMS_DIR}/ there. Train one with "
            f"`{train_expert_command('TASK')}`, or leave --expert_path unset "
            "for the task's shipped expert (HalfCheetah's: experiments/expert)."
        )
    return json.loads(meta_file.read_text())


HALFCHEETAH_OBS_DIM = 17


def expert_task(meta: dict[str, Any]) -> str | None:
    """The task an expert acts in: the `env_name` its exporter recorded (`driver.export_expert`,
    `human.expert.clone_expert`), or None where unknown."""
    recorded = meta.get("env_name")
    if recorded is not None:
        return str(recorded)
    # An expert with no task recorded was saved when HalfCheetah was the only task with physics:
    # one of HalfCheetah's 17 observations is HalfCheetah's (Walker2d's 17 came later, always
    # recorded). Other sizes were the toy stand-in's or unknown: the sizes' check alone applies.
    return "halfcheetah" if meta.get("obs_dim") == HALFCHEETAH_OBS_DIM else None


def check_expert_task(meta: dict[str, Any], path: str | Path, env_name: str) -> None:
    """ValueError unless the expert at `path` (its metadata `meta`) acts in task `env_name`: an
    expert of another task with the same sizes (Walker2d's and HalfCheetah's are both 17 and 6)
    would run without complaint and demonstrate nonsense."""
    task = expert_task(meta)
    if task is not None and task != env_name:
        raise ValueError(
            f"Expert at {Path(path).absolute()} acts in task {task!r}, but this run's task is "
            f"{env_name!r}: leave --expert_path unset for {env_name!r}'s shipped expert, pass the "
            f"directory of an expert of {env_name!r}, or train one with "
            f"`{train_expert_command(env_name)}`."
        )


def load_expert(
    path: str | Path,
    obs_dim: int,
    action_dim: int,
    stochastic: bool = False,
    env_name: str | None = None,
) -> Expert:
    """Load an expert saved by `save_expert`, checking it fits the environment: its task (when
    `env_name` is given, `check_expert_task`) and its sizes.

    Raises FileNotFoundError if nothing is there and ValueError if it does not fit."""
    import orbax.checkpoint as ocp

    path = Path(path).absolute()
    meta = read_expert_meta(path)
    if env_name is not None:
        check_expert_task(meta, path, env_name)
    if (meta.get("obs_dim"), meta.get("action_dim")) != (obs_dim, action_dim):
        raise ValueError(
            f"Expert at {path} was trained for obs_dim={meta.get('obs_dim')}, "
            f"action_dim={meta.get('action_dim')} (task {expert_task(meta)!r}), but "
            f"{'task ' + repr(env_name) if env_name else 'this env'} has obs_dim={obs_dim}, "
            f"action_dim={action_dim}."
        )
    actor = Actor(
        action_dim=action_dim,
        hidden_sizes=tuple(meta["hidden_sizes"]),
        log_std_min=meta.get("log_std_min", -20.0),
        log_std_max=meta.get("log_std_max", 2.0),
        draw_noise=False,  # the expert acts at noise scale 0 (`expert_from_actor`)
    )
    abstract = jax.eval_shape(
        actor.init, jax.random.key(0), jnp.zeros((1, obs_dim)), jax.random.key(0), jnp.float32(0)
    )
    try:
        params = ocp.StandardCheckpointer().restore(path / PARAMS_DIR, abstract)
    except ValueError as err:
        raise ValueError(
            f"Expert at {path} does not match the actor its {META_FILE} describes "
            f"(hidden_sizes={meta['hidden_sizes']}): {err}"
        ) from err
    return expert_from_actor(actor, params, meta, stochastic)
