"""The host side of a person's demonstrations: one thread-safe object between the training loop's
`io_callback` (which blocks in `demonstrate` until the person has acted) and the page's HTTP
handlers (which read the pending step and hand in actions).

Paper A.3 lists the costs of a person as the expert: continuous actions need accurate manipulation,
and the person's time is the bottleneck. Here the person is asked only at the steps the query
strategy demonstrates, and while a step waits for them nothing advances: the loop is blocked inside
the callback, so no env step, no update and no budget is spent meanwhile (there is no timeout).
A pause stops the run at the next point the host is reached (after a demonstrated step, between
chunks, and, once the loop calls `observe`, at every iteration).

Hand-back: the person may give the rest of a query back to the agent. The step is answered with a
row of NaNs, which the loop reads as "declined" (`arld_jax.expert.Expert`): it executes the
agent's proposed action as an ordinary agent step (not is_demo in the replay), cancels the rest of
the query and returns its budget. The dataset records the step with source `handed_back` (the
agent's action), and behaviour cloning leaves it out.

Every refusal is a `RequestError`: an HTTP status, a message naming what was wrong, and what is
allowed; a refused request changes nothing.
"""

from __future__ import annotations

import json
import math
import secrets
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from arld_jax.human.dataset import HANDED_BACK, PERSON, DemoDataset, DemoRecord, latest_by_key

TOKEN_HEADER = "X-Demo-Session"
"""Header carrying the page's session token (one registered page at a time)."""

HISTORY = 4
"""Frames shown: the last few states of the env being demonstrated (paper A.3, "Pros 1")."""


def _declined(action: np.ndarray) -> np.ndarray:
    """The loop's "handed back" answer for one env: a row of NaNs (see `arld_jax.expert.Expert`)."""
    return np.full_like(np.asarray(action, np.float32), np.nan)


class RequestError(Exception):
    """A refused request: HTTP `status`, what was wrong (`error`) and what is allowed."""

    def __init__(self, status: int, error: str, allowed: str | None = None) -> None:
        super().__init__(error)
        self.status, self.error, self.allowed = status, error, allowed

    def body(self) -> dict[str, Any]:
        out: dict[str, Any] = {"error": self.error}
        if self.allowed is not None:
            out["allowed"] = self.allowed
        return out


class SessionClosed(RuntimeError):
    """The demonstration session was closed while the training loop waited for the person."""


@dataclass(frozen=True)
class RunInfo:
    """What the page shows about the run (static for the session)."""

    env_name: str
    obs_dim: int
    action_dim: int
    action_names: tuple[str, ...]
    strategy: str
    uncertainty: str
    demo_steps: int  # C
    budget: int
    total_env_steps: int
    num_envs: int
    query_prob: float
    t_query: float


@dataclass(frozen=True)
class PendingStep:
    """One demonstrated env step waiting for the person."""

    step_id: int  # the global env-step index (env_step + env): unique and stable across restarts
    query: int
    k: int  # step k of c
    c: int
    env: int
    env_step: int
    obs: np.ndarray  # [obs_dim]
    agent_action: np.ndarray  # [A]
    uncertainty: float
    demos_used: int  # this step included
    budget: int
    shown_at: float
    frames: list[dict[str, Any]] = field(default_factory=list)  # oldest first, this step last


# ---------------------------------------------------------------- request validation (pure)


def parse_json_object(raw: bytes) -> dict[str, Any]:
    """The request body as a JSON object, or RequestError(400)."""
    try:
        body = json.loads(raw.decode("utf-8")) if raw.strip() else {}
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise RequestError(
            400,
            f"malformed JSON body: {err}",
            'a JSON object, e.g. {"step_id": 0, "action": [...]}',
        ) from None
    if not isinstance(body, dict):
        raise RequestError(400, f"the body must be a JSON object, got {type(body).__name__}")
    return body


def check_fields(
    body: dict[str, Any], required: tuple[str, ...], optional: tuple[str, ...] = ()
) -> None:
    """RequestError(422) on a missing or unknown field."""
    allowed = ", ".join(required + optional)
    missing = [f for f in required if f not in body]
    if missing:
        raise RequestError(422, f"missing field(s): {', '.join(missing)}", f"fields: {allowed}")
    unknown = sorted(set(body) - set(required) - set(optional))
    if unknown:
        raise RequestError(422, f"unknown field(s): {', '.join(unknown)}", f"fields: {allowed}")


def validate_step_id(value: Any) -> int:
    """A step id is a non-negative integer (the global env-step index of the pending step)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise RequestError(
            422, f"step_id = {value!r} is not a non-negative integer", "the pending step's step_id"
        )
    return value


def validate_action(value: Any, action_names: tuple[str, ...]) -> np.ndarray:
    """The action as float32 [A], or RequestError(422) naming the first bad value."""
    dim = len(action_names)
    allowed = f"a list of {dim} finite numbers in [-1, 1] ({', '.join(action_names)})"
    if not isinstance(value, list):
        raise RequestError(422, f"action must be a list, got {type(value).__name__}", allowed)
    if len(value) != dim:
        raise RequestError(
            422, f"action has {len(value)} values but this env has {dim} action dimensions", allowed
        )
    for i, v in enumerate(value):
        name = f"action[{i}] ({action_names[i]})"
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise RequestError(422, f"{name} = {v!r} is not a number", allowed)
        if not math.isfinite(v):
            raise RequestError(422, f"{name} is {v} (not a finite number)", allowed)
        if not -1.0 <= v <= 1.0:
            raise RequestError(422, f"{name} = {v} is outside [-1, 1]", allowed)
    return np.asarray(value, np.float32)


def _as_list(x: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(x, np.float64).ravel()]


# ---------------------------------------------------------------- the session


class DemoSession:
    """Thread-safe meeting point of the training loop and the page (one `threading.Condition`).

    Loop side: `demonstrate` (the io_callback body), `observe`, `set_status`, `wait_while_paused`.
    Page side: `register`, `snapshot`, `submit`, `hand_back`, `set_paused` (each raises
    RequestError and changes nothing when it refuses). `close` releases a waiting loop with
    SessionClosed."""

    def __init__(
        self,
        run: RunInfo,
        dataset: DemoDataset,
        frame_fn: Callable[[np.ndarray], dict[str, Any]] | None = None,
        history: int = HISTORY,
        clock: Callable[[], float] = time.time,
        log: Callable[..., None] = print,
    ) -> None:
        self.run, self.dataset, self.frame_fn, self.clock, self.log = (
            run,
            dataset,
            frame_fn,
            clock,
            log,
        )
        self._cv = threading.Condition()
        self._token: str | None = None
        self._pending: PendingStep | None = None
        self._answered = False
        self._answer: np.ndarray | None = None
        self._closed = False
        self._paused = False
        self._status = "starting"
        self._progress: dict[str, Any] = {}
        self._handed_back: set[int] = set()
        self._runs: dict[int, tuple[int, int]] = {}  # env -> (query, c) of its current run
        self._known = latest_by_key(dataset.records)
        self._next_query = 1 + max((r.query for r in dataset.records), default=-1)
        self._history: dict[int, deque[tuple[int, np.ndarray, bool]]] = {}  # (step, obs, fell)
        self._falls: list[dict[str, int]] = []  # {"env", "env_step"} of each fall, in order
        self._history_len = history
        self._last_submitted: list[float] | None = None
        self.counts = {"asked": 0, "replayed": 0, "handed_back": 0}

    # ------------------------------------------------------------ loop side

    def demonstrate(
        self,
        obs: Any,
        agent_action: Any,
        uncertainty: Any,
        is_demo: Any,
        new_query: Any,
        demo_remaining: Any,
        demos_used: Any,
        budget: Any,
        env_step: Any,
    ) -> np.ndarray:
        """The actions of one iteration [n, A] float32: the person's where `is_demo`, asked env by
        env; the agent's proposal elsewhere (unused by the loop). Blocks until answered.

        A step already in the dataset (a resumed run reaching it again, same state) is answered
        from it without asking: already-given demonstrations are not asked again."""
        obs = np.asarray(obs, np.float32)
        out = np.array(agent_action, np.float32, copy=True)
        is_demo, new_query = np.asarray(is_demo, bool), np.asarray(new_query, bool)
        demo_remaining, u = np.asarray(demo_remaining), np.asarray(uncertainty, np.float32)
        step0, used, budget = int(env_step), int(demos_used), int(budget)
        for e in np.flatnonzero(is_demo):
            e = int(e)
            query, c = self._run_of(e, bool(new_query[e]), int(demo_remaining[e]), step0)
            self._remember(e, step0, obs[e])
            known = self._known.get((step0, e))
            if known is not None and np.allclose(known.obs, obs[e], atol=1e-5):
                out[e] = np.asarray(known.action, np.float32)
                self.counts["replayed"] += 1
                continue
            if known is not None:
                self.log(
                    f"warning: the recorded demonstration at env step {step0} (env {e}) was for "
                    "another state (the run diverged from the recorded one); asking again"
                )
            pending = PendingStep(
                step_id=step0 + e,
                query=query,
                k=c - int(demo_remaining[e]),
                c=c,
                env=e,
                env_step=step0,
                obs=obs[e].copy(),
                agent_action=out[e].copy(),
                uncertainty=float(u[e]),
                demos_used=used,
                budget=budget,
                shown_at=self.clock(),
                frames=self._frames(e),
            )
            out[e] = self._ask(pending)
            self.wait_while_paused()
        return out

    def observe(self, obs: Any, next_obs: Any, fell: Any, env_step: Any) -> np.int32:
        """After an iteration's env step: remember every env's state (the frames before a query),
        and for each env that fell, the state it fell into, shown as the end of its episode (the
        env restarts from a fresh state). Then hold while paused. The loop's per-iteration hook
        (see the package docstring); returns a dummy int32."""
        obs, next_obs = np.asarray(obs, np.float32), np.asarray(next_obs, np.float32)
        step, num_envs = int(env_step), obs.shape[0]
        for e in range(num_envs):
            self._remember(e, step, obs[e])
        for e in np.flatnonzero(np.asarray(fell, bool)):
            e, fell_at = int(e), step + num_envs  # the fallen state: where the next step would act
            self._remember(e, fell_at, next_obs[e], fell=True)
            with self._cv:
                self._falls.append({"env": e, "env_step": fell_at})
            self.log(f"env {e} fell at env step {fell_at}: its episode ended, a new one begins")
        self.wait_while_paused()
        return np.int32(0)

    def _run_of(self, env: int, new: bool, remaining: int, env_step: int) -> tuple[int, int]:
        """(query index, c) of the run env `env` is in at this demonstrated step."""
        with self._cv:
            known = self._known.get((env_step, env))
            if new or env not in self._runs:
                if known is not None:
                    query, c = known.query, known.c
                elif not new and (last := self._last_record_of(env)) is not None:
                    query, c = (
                        last.query,
                        last.c,
                    )  # resumed inside a run begun before the checkpoint
                else:
                    query, c = self._next_query, remaining + 1
                self._next_query = max(self._next_query, query + 1)
                self._runs[env] = (query, c)
            return self._runs[env]

    def _last_record_of(self, env: int) -> DemoRecord | None:
        mine = [r for r in self._known.values() if r.env == env]
        return max(mine, key=lambda r: r.env_step) if mine else None

    def _remember(self, env: int, env_step: int, obs: np.ndarray, fell: bool = False) -> None:
        """Append env `env`'s state at `env_step` once. A fallen state and the fresh state that
        replaces it share their env step: both are kept, the fall first."""
        with self._cv:
            hist = self._history.setdefault(env, deque(maxlen=self._history_len))
            if not hist or hist[-1][0] != env_step or hist[-1][2] != fell:
                hist.append((env_step, np.array(obs, np.float32), fell))

    def _frames(self, env: int) -> list[dict[str, Any]]:
        with self._cv:
            hist = list(self._history.get(env, ()))
        frames = []
        for step, obs, fell in hist:
            frame: dict[str, Any] = {"env_step": step, "obs": _as_list(obs), "fell": fell}
            if self.frame_fn is not None:
                frame |= self.frame_fn(obs)
            frames.append(frame)
        return frames

    def _ask(self, pending: PendingStep) -> np.ndarray:
        """Publish `pending` and wait for the person's answer (or the query's hand-back)."""
        with self._cv:
            if self._closed:
                raise SessionClosed("the demonstration session is closed")
            if pending.query in self._handed_back:
                self._record(pending, pending.agent_action, HANDED_BACK)
                self.counts["handed_back"] += 1
                return _declined(pending.agent_action)
            self._pending, self._answered, self._answer = pending, False, None
            self.counts["asked"] += 1
            self._cv.notify_all()
            while not self._answered and not self._closed:
                self._cv.wait(timeout=0.5)
            self._pending = None
            if not self._answered:
                raise SessionClosed("the demonstration session was closed during a query")
            assert self._answer is not None
            return self._answer

    def _record(self, pending: PendingStep, action: np.ndarray, source: str) -> DemoRecord:
        """Write the step to the dataset (flushed) before the loop gets the action. Under _cv."""
        record = DemoRecord(
            query=pending.query,
            k=pending.k,
            c=pending.c,
            env=pending.env,
            env_step=pending.env_step,
            obs=_as_list(pending.obs),
            action=_as_list(action),
            agent_action=_as_list(pending.agent_action),
            uncertainty=pending.uncertainty,
            demos_used=pending.demos_used,
            budget=pending.budget,
            source=source,
            shown_at=pending.shown_at,
            answered_at=self.clock(),
        )
        self.dataset.append(record)
        self._known[record.key] = record
        return record

    def wait_while_paused(self) -> None:
        """Block while the person has paused the run (nothing advances, nothing is spent)."""
        with self._cv:
            while self._paused and not self._closed:
                self._cv.wait(timeout=0.5)
            if self._closed:
                raise SessionClosed("the demonstration session is closed")

    def set_status(self, status: str, **progress: Any) -> None:
        """Loop/driver status for the page: compiling, training, finished, error ..."""
        with self._cv:
            self._status = status
            self._progress |= progress
            self._cv.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Release a waiting loop (it raises SessionClosed) and refuse further waits."""
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    # ------------------------------------------------------------ page side

    def _check_token(self, token: str | None) -> None:
        if not token:
            raise RequestError(
                401,
                f"no session: missing {TOKEN_HEADER} header",
                "register first with POST /api/session (the page does this when it opens)",
            )
        if token != self._token:
            raise RequestError(
                403,
                "this tab is not the demonstration page any more: the session was taken over by "
                "another tab (or the server restarted)",
                "reload the page to take over again",
            )

    def register(self, body: dict[str, Any]) -> dict[str, Any]:
        """Register the page; a second tab is refused unless it asks to take over explicitly
        ({"take_over": true}), which makes the first tab's token invalid (it gets 403)."""
        check_fields(body, (), ("take_over",))
        take_over = body.get("take_over", False)
        if not isinstance(take_over, bool):
            raise RequestError(422, f"take_over = {take_over!r} is not a boolean", "true or false")
        with self._cv:
            if self._token is not None and not take_over:
                raise RequestError(
                    409,
                    "the demonstration page is already open in another tab (one page per run, "
                    "so that two tabs never answer the same step)",
                    'close the other tab, or take over here: POST /api/session {"take_over": true}',
                )
            took_over = self._token is not None
            self._token = secrets.token_urlsafe(16)
            return {"token": self._token, "took_over": took_over}

    def snapshot(self, token: str | None) -> dict[str, Any]:
        """Everything the page shows, as JSON-ready data."""
        with self._cv:
            self._check_token(token)
            p = self._pending if not self._answered else None
            pending = None
            if p is not None:
                pending = {
                    "step_id": p.step_id,
                    "query": p.query,
                    "k": p.k,
                    "c": p.c,
                    "env": p.env,
                    "env_step": p.env_step,
                    "obs": _as_list(p.obs),
                    "agent_action": _as_list(p.agent_action),
                    "uncertainty": p.uncertainty,
                    "demos_used": p.demos_used,
                    "budget_left": p.budget - p.demos_used,
                    "frames": p.frames,
                }
            status = "waiting" if pending else ("paused" if self._paused else self._status)
            return {
                "status": status,
                "paused": self._paused,
                "run": asdict(self.run),
                "progress": dict(self._progress),
                "pending": pending,
                "recorded": len(self.dataset.records),
                "last_submitted": self._last_submitted,
                "falls": len(self._falls),
                "last_fall": self._falls[-1] if self._falls else None,
            }

    def _pending_step(self, step_id: int, what: str) -> PendingStep:
        if self._pending is None or self._answered:
            raise RequestError(
                409,
                f"no demonstration is pending, so there is nothing to {what} (run status: "
                f"{self._status}); the strategy has not queried",
                "wait until the page shows a query (GET /api/state has a 'pending' step)",
            )
        if step_id != self._pending.step_id:
            raise RequestError(
                409,
                f"stale step_id {step_id}: the pending step is {self._pending.step_id}",
                f"step_id {self._pending.step_id}",
            )
        return self._pending

    def _answer_with(self, pending: PendingStep, action: np.ndarray, source: str) -> DemoRecord:
        record = self._record(pending, action, source)
        self._answered, self._answer = True, action
        self._cv.notify_all()
        return record

    def submit(self, token: str | None, body: dict[str, Any]) -> dict[str, Any]:
        """The person's action for the pending step: {"step_id": int, "action": [A numbers]}."""
        with self._cv:
            self._check_token(token)
            check_fields(body, ("step_id", "action"))
            step_id = validate_step_id(body["step_id"])
            action = validate_action(body["action"], self.run.action_names)
            pending = self._pending_step(step_id, "submit")
            record = self._answer_with(pending, action, PERSON)
            self._last_submitted = record.action
            return {"ok": True, "recorded": asdict(record)}

    def hand_back(self, token: str | None, body: dict[str, Any]) -> dict[str, Any]:
        """Give the rest of the pending step's query back to the agent: {"step_id": int}."""
        with self._cv:
            self._check_token(token)
            check_fields(body, ("step_id",))
            pending = self._pending_step(validate_step_id(body["step_id"]), "hand back")
            self._handed_back.add(pending.query)
            self.counts["handed_back"] += 1
            record = self._record(pending, pending.agent_action, HANDED_BACK)
            self._answered, self._answer = True, _declined(pending.agent_action)
            self._cv.notify_all()
            return {"ok": True, "recorded": asdict(record)}

    def set_paused(self, token: str | None, body: dict[str, Any]) -> dict[str, Any]:
        """Pause or resume the run: {"paused": bool}."""
        with self._cv:
            self._check_token(token)
            check_fields(body, ("paused",))
            paused = body["paused"]
            if not isinstance(paused, bool):
                raise RequestError(422, f"paused = {paused!r} is not a boolean", "true or false")
            self._paused = paused
            self._cv.notify_all()
            return {"ok": True, "paused": paused}
