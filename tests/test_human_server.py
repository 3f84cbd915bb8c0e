"""The demonstration server without a browser: request handling (starlette's TestClient), every
refusal (and that a refused request records nothing), hand-back, pause, the dataset, resuming a
run that replays given demonstrations, HalfCheetah frames, and behaviour cloning on the toy env."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import jax
import numpy as np
import pytest
from starlette.testclient import TestClient

from arld_jax.config import tiny
from arld_jax.human.dataset import (
    DATASET_FILE,
    HANDED_BACK,
    PERSON,
    DemoDataset,
    DemoRecord,
    read_dataset,
)
from arld_jax.human.server import make_app
from arld_jax.human.session import TOKEN_HEADER, DemoSession, RunInfo, SessionClosed

NAMES = ("a0", "a1", "a2")
WAIT = 60.0  # seconds a test waits for a thread before failing (never a timing assertion)


def make_session(tmp_path: Path, names: tuple[str, ...] = NAMES) -> DemoSession:
    info = RunInfo(
        env_name="toy",
        obs_dim=2,
        action_dim=len(names),
        action_names=names,
        strategy="greedy",
        uncertainty="intrinsic",
        demo_steps=2,
        budget=10,
        total_env_steps=100,
        num_envs=1,
        query_prob=0.1,
        t_query=0.1,
    )
    header = {"env_name": "toy", "obs_dim": 2, "action_dim": len(names)}
    return DemoSession(info, DemoDataset(tmp_path / DATASET_FILE, header), log=lambda *a: None)


class Loop:
    """The training loop's side: `session.demonstrate` for one env in a thread."""

    def __init__(
        self,
        session: DemoSession,
        env_step: int = 0,
        new: bool = True,
        remaining: int = 1,
        obs=(0.5, -0.25),
    ) -> None:  # noqa: ANN001
        self.result: list = []
        self.args = (
            np.asarray([obs], np.float32),  # obs [1, 2]
            np.asarray([[0.1, 0.2, 0.3]], np.float32),  # agent's action
            np.asarray([0.7], np.float32),  # u(s)
            np.asarray([True]),
            np.asarray([new]),
            np.asarray([remaining], np.int32),
            np.int32(env_step // 1 + 1),
            np.int32(10),
            np.int32(env_step),
        )
        self.thread = threading.Thread(target=self._run, args=(session,), daemon=True)
        self.thread.start()

    def _run(self, session: DemoSession) -> None:
        try:
            self.result.append(session.demonstrate(*self.args))
        except SessionClosed as err:
            self.result.append(err)

    def join(self) -> np.ndarray:
        self.thread.join(WAIT)
        assert not self.thread.is_alive(), "the loop is still waiting"
        return self.result[0]


def wait_pending(client: TestClient, token: str, step_id: int) -> dict:
    """Poll the state until step `step_id` is pending (bounded by WAIT, not asserted on time)."""
    import time

    deadline = time.time() + WAIT
    while time.time() < deadline:
        state = client.get("/api/state", headers={TOKEN_HEADER: token}).json()
        if state["pending"] and state["pending"]["step_id"] == step_id:
            return state
        time.sleep(0.01)
    raise AssertionError(f"step {step_id} never became pending")


@pytest.fixture
def setup(tmp_path: Path):  # noqa: ANN201
    session = make_session(tmp_path)
    client = TestClient(make_app(session), base_url="http://127.0.0.1")
    token = client.post("/api/session", json={}).json()["token"]
    yield session, client, token
    session.close()


def post(client: TestClient, path: str, token: str | None, body) -> object:  # noqa: ANN001
    headers = {TOKEN_HEADER: token} if token else {}
    if isinstance(body, bytes | str):
        return client.post(
            path, content=body, headers=headers | {"content-type": "application/json"}
        )
    return client.post(path, json=body, headers=headers)


# ---------------------------------------------------------------- pages and sessions


def test_page_and_script_are_served(setup) -> None:  # noqa: ANN001
    _, client, _ = setup
    page = client.get("/")
    assert page.status_code == 200 and "/demonstrate.js" in page.text
    script = client.get("/demonstrate.js")
    assert script.status_code == 200 and "X-Demo-Session" in script.text


def test_other_hosts_are_refused(tmp_path: Path) -> None:
    """Only 127.0.0.1/localhost Host headers (no DNS rebinding from a page elsewhere)."""
    client = TestClient(make_app(make_session(tmp_path)), base_url="http://evil.example")
    assert client.get("/").status_code == 400


def test_second_tab_is_refused_until_it_takes_over(setup) -> None:  # noqa: ANN001
    session, client, token = setup
    second = client.post("/api/session", json={})
    assert second.status_code == 409
    assert "already open in another tab" in second.json()["error"]
    assert "take_over" in second.json()["allowed"]
    taken = client.post("/api/session", json={"take_over": True})
    assert taken.status_code == 200 and taken.json()["took_over"]
    old = client.get("/api/state", headers={TOKEN_HEADER: token})
    assert old.status_code == 403 and "taken over" in old.json()["error"]
    new = client.get("/api/state", headers={TOKEN_HEADER: taken.json()["token"]})
    assert new.status_code == 200 and new.json()["run"]["action_names"] == list(NAMES)


@pytest.mark.parametrize(
    "body, fragment",
    [({"take_over": "yes"}, "not a boolean"), ({"tab": 1}, "unknown field"), (b"{", "malformed")],
)
def test_bad_registration(setup, body, fragment) -> None:  # noqa: ANN001
    _, client, _ = setup
    resp = post(client, "/api/session", None, body)
    assert 400 <= resp.status_code < 500 and fragment in resp.json()["error"]


def test_state_needs_a_session(setup) -> None:  # noqa: ANN001
    _, client, _ = setup
    resp = client.get("/api/state")
    assert resp.status_code == 401 and "X-Demo-Session" in resp.json()["error"]


# ---------------------------------------------------------------- submitting


def test_submit_records_the_step_and_returns_the_action(setup, tmp_path: Path) -> None:  # noqa: ANN001
    session, client, token = setup
    loop = Loop(session, env_step=7, remaining=1)  # step 1 of 2
    state = wait_pending(client, token, 7)
    p = state["pending"]
    assert (p["query"], p["k"], p["c"], p["env"], p["budget_left"]) == (0, 1, 2, 0, 2)
    assert p["agent_action"] == pytest.approx([0.1, 0.2, 0.3])
    assert p["uncertainty"] == pytest.approx(0.7)
    assert p["obs"] == [0.5, -0.25] and len(p["frames"]) == 1 and state["status"] == "waiting"
    resp = post(client, "/api/action", token, {"step_id": 7, "action": [0.25, -1, 1.0]})
    assert resp.status_code == 200, resp.text
    out = loop.join()
    np.testing.assert_array_equal(out, np.asarray([[0.25, -1, 1]], np.float32))
    header, records = read_dataset(tmp_path / DATASET_FILE)
    assert header["format"] == "arld_jax.demonstrations/1"
    (r,) = records
    assert (r.query, r.k, r.c, r.env, r.env_step, r.source) == (0, 1, 2, 0, 7, PERSON)
    assert r.action == [0.25, -1.0, 1.0] and r.obs == [0.5, -0.25]
    assert r.agent_action == pytest.approx([0.1, 0.2, 0.3]) and r.uncertainty == pytest.approx(0.7)
    assert r.answered_at >= r.shown_at > 0
    # Answered: the same step again is refused, and nothing more is recorded.
    again = post(client, "/api/action", token, {"step_id": 7, "action": [0, 0, 0]})
    assert again.status_code == 409 and "no demonstration is pending" in again.json()["error"]
    assert len(read_dataset(tmp_path / DATASET_FILE)[1]) == 1


BAD_ACTIONS = [
    ({"step_id": 3, "action": [0, 1.5, 0]}, 422, "action[1] (a1) = 1.5 is outside [-1, 1]"),
    ({"step_id": 3, "action": [-1.01, 0, 0]}, 422, "outside [-1, 1]"),
    (b'{"step_id": 3, "action": [0, NaN, 0]}', 422, "action[1] (a1) is nan"),
    (b'{"step_id": 3, "action": [Infinity, 0, 0]}', 422, "not a finite number"),
    ({"step_id": 3, "action": [0, None, 0]}, 422, "action[1] (a1) = None is not a number"),
    ({"step_id": 3, "action": [0, "0.5", 0]}, 422, "is not a number"),
    ({"step_id": 3, "action": [True, 0, 0]}, 422, "is not a number"),
    ({"step_id": 3, "action": [0, 0]}, 422, "has 2 values but this env has 3 action dimensions"),
    ({"step_id": 3, "action": [0, 0, 0, 0]}, 422, "has 4 values"),
    ({"step_id": 3, "action": 0.5}, 422, "action must be a list"),
    ({"step_id": 3}, 422, "missing field(s): action"),
    ({"action": [0, 0, 0]}, 422, "missing field(s): step_id"),
    ({"step_id": 3, "action": [0, 0, 0], "note": 1}, 422, "unknown field(s): note"),
    ({"step_id": "3", "action": [0, 0, 0]}, 422, "step_id = '3' is not a non-negative integer"),
    ({"step_id": -1, "action": [0, 0, 0]}, 422, "not a non-negative integer"),
    ({"step_id": 2, "action": [0, 0, 0]}, 409, "stale step_id 2: the pending step is 3"),
    (b'{"step_id": 3, "action": [0, 0', 400, "malformed JSON body"),
    (b"[0, 0, 0]", 400, "must be a JSON object"),
]


@pytest.mark.parametrize("body, status, fragment", BAD_ACTIONS)
def test_bad_actions_are_refused_and_record_nothing(
    setup, tmp_path, body, status, fragment
) -> None:  # noqa: ANN001
    session, client, token = setup
    loop = Loop(session, env_step=3)
    wait_pending(client, token, 3)
    before = (tmp_path / DATASET_FILE).read_bytes()
    resp = post(client, "/api/action", token, body)
    assert resp.status_code == status, resp.text
    assert fragment in resp.json()["error"], resp.json()
    if status == 422:
        assert "allowed" in resp.json()
    # Nothing changed: same file, same pending step, the loop still waits.
    assert (tmp_path / DATASET_FILE).read_bytes() == before
    assert wait_pending(client, token, 3)["recorded"] == 0
    assert loop.thread.is_alive()
    ok = post(client, "/api/action", token, {"step_id": 3, "action": [0.5, 0.5, 0.5]})
    assert ok.status_code == 200
    np.testing.assert_array_equal(loop.join(), [[0.5, 0.5, 0.5]])


def test_action_without_a_pending_query_is_refused(setup, tmp_path: Path) -> None:  # noqa: ANN001
    _, client, token = setup
    before = (tmp_path / DATASET_FILE).read_bytes()
    resp = post(client, "/api/action", token, {"step_id": 0, "action": [0, 0, 0]})
    assert resp.status_code == 409 and "no demonstration is pending" in resp.json()["error"]
    hb = post(client, "/api/hand_back", token, {"step_id": 0})
    assert hb.status_code == 409
    assert (tmp_path / DATASET_FILE).read_bytes() == before


def test_requests_from_a_replaced_tab_record_nothing(setup, tmp_path: Path) -> None:  # noqa: ANN001
    session, client, token = setup
    loop = Loop(session, env_step=0)
    wait_pending(client, token, 0)
    new_token = client.post("/api/session", json={"take_over": True}).json()["token"]
    before = (tmp_path / DATASET_FILE).read_bytes()
    for path, body in [
        ("/api/action", {"step_id": 0, "action": [0, 0, 0]}),
        ("/api/hand_back", {"step_id": 0}),
        ("/api/pause", {"paused": True}),
    ]:
        assert post(client, path, token, body).status_code == 403
        assert post(client, path, None, body).status_code == 401
    assert (tmp_path / DATASET_FILE).read_bytes() == before
    assert not wait_pending(client, new_token, 0)["paused"]
    post(client, "/api/action", new_token, {"step_id": 0, "action": [0, 0, 0]})
    loop.join()


# ---------------------------------------------------------------- hand-back, pause, closing


def test_hand_back_gives_the_rest_of_the_query_to_the_agent(setup, tmp_path: Path) -> None:  # noqa: ANN001
    session, client, token = setup
    first = Loop(session, env_step=0, new=True, remaining=2)  # step 1 of 3
    wait_pending(client, token, 0)
    assert post(client, "/api/hand_back", token, {"step_id": 0}).status_code == 200
    # NaNs tell the loop "declined": it runs the agent's action, cancels the query, refunds it.
    assert np.all(np.isnan(first.join()))
    second = Loop(session, env_step=1, new=False, remaining=1)  # answered without asking
    assert np.all(np.isnan(second.join()))
    assert session.counts["asked"] == 1
    third = Loop(session, env_step=2, new=True, remaining=0)  # a new query asks again
    wait_pending(client, token, 2)
    post(client, "/api/action", token, {"step_id": 2, "action": [0, 0, 0]})
    third.join()
    records = read_dataset(tmp_path / DATASET_FILE)[1]
    assert [(r.query, r.k, r.c, r.source) for r in records] == [
        (0, 1, 3, HANDED_BACK),
        (0, 2, 3, HANDED_BACK),
        (1, 1, 1, PERSON),
    ]


def test_a_fall_is_shown_before_the_next_query(setup) -> None:  # noqa: ANN001
    """The loop's `observe` after each env step: the state an env fell into is kept as a frame
    marked `fell`, before the fresh state of its next episode, and the page's state counts the
    falls and names the last one."""
    session, client, token = setup
    state = lambda: client.get("/api/state", headers={TOKEN_HEADER: token}).json()  # noqa: E731
    obs = lambda v: np.asarray([[v, -v]], np.float32)  # noqa: E731
    session.observe(obs(0.1), obs(0.2), np.asarray([False]), np.int32(0))
    assert (state()["falls"], state()["last_fall"]) == (0, None)
    session.observe(obs(0.2), obs(0.9), np.asarray([True]), np.int32(1))  # fell into 0.9 at step 2
    assert (state()["falls"], state()["last_fall"]) == (1, {"env": 0, "env_step": 2})
    loop = Loop(session, env_step=2, obs=(0.4, -0.4))  # a query on the fresh state at step 2
    frames = wait_pending(client, token, 2)["pending"]["frames"]
    assert [(f["env_step"], f["obs"][0], f["fell"]) for f in frames] == [
        (0, pytest.approx(0.1), False),
        (1, pytest.approx(0.2), False),
        (2, pytest.approx(0.9), True),
        (2, pytest.approx(0.4), False),
    ]
    post(client, "/api/action", token, {"step_id": 2, "action": [0, 0, 0]})
    loop.join()


def test_pause_holds_the_loop_after_the_answer(setup) -> None:  # noqa: ANN001
    session, client, token = setup
    assert post(client, "/api/pause", token, {"paused": "no"}).status_code == 422
    assert post(client, "/api/pause", token, {"paused": True}).json()["paused"] is True
    loop = Loop(session, env_step=0)
    wait_pending(client, token, 0)
    post(client, "/api/action", token, {"step_id": 0, "action": [0, 0, 0]})
    loop.thread.join(0.3)
    assert loop.thread.is_alive(), "the loop went on while paused"
    assert client.get("/api/state", headers={TOKEN_HEADER: token}).json()["status"] == "paused"
    post(client, "/api/pause", token, {"paused": False})
    loop.join()


def test_closing_releases_a_waiting_loop(setup) -> None:  # noqa: ANN001
    session, client, token = setup
    loop = Loop(session, env_step=0)
    wait_pending(client, token, 0)
    session.close()
    assert isinstance(loop.join(), SessionClosed)


# ---------------------------------------------------------------- dataset


def _record(env_step: int, action: list[float], source: str = PERSON) -> DemoRecord:
    return DemoRecord(
        0, 1, 1, 0, env_step, [0.0, 1.0], action, [0.0] * 3, 0.5, 1, 10, source, 1.0, 2.0
    )


def test_dataset_survives_a_half_written_line(tmp_path: Path) -> None:
    header = {"env_name": "toy", "obs_dim": 2, "action_dim": 3}
    ds = DemoDataset(tmp_path / DATASET_FILE, header)
    ds.append(_record(0, [0.1, 0.2, 0.3]))
    with open(tmp_path / DATASET_FILE, "a") as f:
        f.write('{"kind": "demo", "query": 0, "k"')  # a crash mid-write
    assert len(read_dataset(tmp_path / DATASET_FILE)[1]) == 1
    reopened = DemoDataset(tmp_path / DATASET_FILE, header)
    reopened.append(_record(1, [0.4, 0.5, 0.6]))
    assert [r.env_step for r in read_dataset(tmp_path / DATASET_FILE)[1]] == [0, 1]
    with pytest.raises(ValueError, match="action_dim=3"):
        DemoDataset(tmp_path / DATASET_FILE, header | {"action_dim": 6})


def test_resumed_session_replays_given_steps_and_asks_on_divergence(tmp_path: Path) -> None:
    session = make_session(tmp_path)
    client = TestClient(make_app(session), base_url="http://127.0.0.1")
    token = client.post("/api/session", json={}).json()["token"]
    loop = Loop(session, env_step=5, remaining=1)
    wait_pending(client, token, 5)
    post(client, "/api/action", token, {"step_id": 5, "action": [0.9, -0.9, 0.0]})
    loop.join()
    session.close()

    resumed = make_session(tmp_path)  # a new process on the same run directory
    same = Loop(resumed, env_step=5, remaining=1)  # same state: not asked again
    np.testing.assert_allclose(same.join(), [[0.9, -0.9, 0.0]])
    assert resumed.counts == {"asked": 0, "replayed": 1, "handed_back": 0}
    next_step = Loop(resumed, env_step=6, new=False, remaining=0)  # step 2 of the same query
    client = TestClient(make_app(resumed), base_url="http://127.0.0.1")
    token = client.post("/api/session", json={}).json()["token"]
    p = wait_pending(client, token, 6)["pending"]
    assert (p["query"], p["k"], p["c"]) == (0, 2, 2)
    post(client, "/api/action", token, {"step_id": 6, "action": [0, 0, 0]})
    next_step.join()
    other = Loop(resumed, env_step=5, remaining=1, obs=(0.0, 0.0))  # another state: asked
    wait_pending(client, token, 5)
    resumed.close()
    assert isinstance(other.join(), SessionClosed)


# ---------------------------------------------------------------- frames


def test_halfcheetah_frame_is_the_model_at_the_observed_pose() -> None:
    from arld_jax.human.frames import halfcheetah_action_names, halfcheetah_frame, kinematics

    assert halfcheetah_action_names() == ["bthigh", "bshin", "bfoot", "fthigh", "fshin", "ffoot"]
    obs = np.zeros(17)
    obs[0], obs[1] = 0.1, 0.3  # rootz (+0.1 m), pitch (0.3 rad)
    frame = halfcheetah_frame(obs)
    seg = {s["name"]: s for s in frame["segments"]}
    assert list(seg) == ["torso", "head", "bthigh", "bshin", "bfoot", "fthigh", "fshin", "ffoot"]
    torso = seg["torso"]  # fromto -0.5..0.5 along x, at 0.7 + rootz, pitched by rooty
    length = np.hypot(torso["x2"] - torso["x1"], torso["z2"] - torso["z1"])
    assert length == pytest.approx(1.0, abs=1e-4)
    assert (torso["z1"] + torso["z2"]) / 2 == pytest.approx(0.8, abs=1e-4)
    # rooty is a rotation about +y: the front end (larger x) goes down for a positive angle.
    front, back = sorted([(torso["x1"], torso["z1"]), (torso["x2"], torso["z2"])], reverse=True)
    assert front[1] - back[1] == pytest.approx(-np.sin(0.3), abs=1e-4)
    head = seg["head"]  # the head is at the front, above the torso's front end
    assert min(head["x1"], head["x2"]) > 0.3
    # The page's segments are the geoms MuJoCo places (centre = mean of the end points).
    data = kinematics(np.concatenate([[0.0], obs[:8]]))
    centre = np.asarray([(torso["x1"] + torso["x2"]) / 2, (torso["z1"] + torso["z2"]) / 2])
    np.testing.assert_allclose(centre, data.geom_xpos[1][[0, 2]], atol=1e-4)


# ---------------------------------------------------------------- the loop and resuming (toy env)


class AutoPerson:
    """A scripted person on the HTTP API: answers every step with action(step_id)."""

    def __init__(self, session: DemoSession, stop_after: int | None = None) -> None:
        self.client = TestClient(make_app(session), base_url="http://127.0.0.1")
        self.token = self.client.post("/api/session", json={}).json()["token"]
        self.sent: dict[int, list[float]] = {}
        self.session, self.stop_after = session, stop_after
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    @staticmethod
    def action(step_id: int) -> list[float]:
        return [round(np.sin(step_id) * 0.9, 3), round(np.cos(step_id) * 0.9, 3)]

    def _run(self) -> None:
        import time

        while not self.session.closed:
            p = self.client.get("/api/state", headers={TOKEN_HEADER: self.token}).json()["pending"]
            if p and p["step_id"] not in self.sent:
                if self.stop_after is not None and len(self.sent) >= self.stop_after:
                    self.session.close()  # the person's process dies mid-chunk
                    return
                a = self.action(p["step_id"])
                body = {"step_id": p["step_id"], "action": a}
                if self.client.post(
                    "/api/action", json=body, headers={TOKEN_HEADER: self.token}
                ).is_success:
                    self.sent[p["step_id"]] = a
            time.sleep(0.005)


def test_run_with_person_resumes_without_asking_again(tmp_path: Path) -> None:
    """Greedy on the toy env, 2 envs: the replay's demonstrations are exactly the person's actions;
    after a crash mid-chunk, the rerun resumes from the checkpoint, replays the steps answered
    since from the dataset (same states), and asks only the rest."""
    from arld_jax.driver import RunOptions
    from arld_jax.human.cli import open_session, run_with_person

    # 5 iterations (10 env steps) per chunk; greedy asks at iterations 0-7 (16 steps, C = 3).
    cfg = tiny(
        strategy="greedy",
        demo_steps=3,
        budget=16,
        total_env_steps=60,
        learning_starts=20,
        eval_every=10,
        traces_per_eval=5,
        replay_capacity=60,
        window_size=10,
        episode_length=20,
    )
    quiet = lambda *a: None  # noqa: E731

    def demo_actions(state) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
        size = int(state.replay.size)
        data = jax.tree.map(lambda x: np.asarray(x)[:size], state.replay.data)
        return data.obs[data.is_demo == 1], data.action[data.is_demo == 1]

    # The person's process dies after 12 answers: 10 in chunk 1 (checkpointed), 2 in chunk 2.
    options = RunOptions(chunk_periods=1, plots=False, log=quiet)
    broken = tmp_path / "broken"
    broken.mkdir()
    session = open_session(cfg, broken, quiet)
    AutoPerson(session, stop_after=12)
    with pytest.raises(Exception):  # noqa: B017 (XLA wraps the callback's SessionClosed)
        run_with_person(cfg, broken, session, options)
    assert len(read_dataset(broken / DATASET_FILE)[1]) == 12
    session = open_session(cfg, broken, quiet)
    AutoPerson(session)
    result = run_with_person(cfg, broken, session, options)
    session.close()
    assert result["complete"]
    assert session.counts == {"asked": 4, "replayed": 2, "handed_back": 0}
    assert len(read_dataset(broken / DATASET_FILE)[1]) == 16
    obs, actions = demo_actions(result["state"])
    records = read_dataset(broken / DATASET_FILE)[1]
    ids = [r.env_step + r.env for r in records]
    assert ids == sorted(set(ids)) and len(ids) == 16  # each step once, in loop order
    expected = np.asarray([AutoPerson.action(r.env_step + r.env) for r in records], np.float32)
    np.testing.assert_array_equal(actions, expected)  # replay order = record order (env order)
    np.testing.assert_array_equal(obs, np.asarray([r.obs for r in records], np.float32))
    assert json.loads((broken / "config.json").read_text())["mode"] == "human"


# ---------------------------------------------------------------- behaviour cloning


def test_cloned_expert_reproduces_the_recorded_actions(tmp_path: Path) -> None:
    """Record the toy expert's actions as a person's demonstrations, clone them into a saved
    expert, load it as `--expert_path` would, and compare on the recorded states."""
    from arld_jax.envs import toy_target_action
    from arld_jax.expert import load_expert
    from arld_jax.human.expert import clone_expert

    rng = np.random.default_rng(0)
    obs = rng.uniform(-1, 1, size=(300, 4)).astype(np.float32)
    actions = np.asarray(toy_target_action(obs))
    ds = DemoDataset(tmp_path / DATASET_FILE, {"env_name": "toy", "obs_dim": 4, "action_dim": 2})
    for i, (o, a) in enumerate(zip(obs, actions, strict=True)):
        ds.append(
            DemoRecord(
                i // 3,
                i % 3 + 1,
                3,
                0,
                i,
                o.tolist(),
                a.tolist(),
                [0.0, 0.0],
                0.1,
                i + 1,
                300,
                PERSON,
                0.0,
                0.0,
            )
        )
    ds.append(
        DemoRecord(
            999,
            1,
            1,
            0,
            10_000,
            [9.0] * 4,
            [1.0, 1.0],
            [1.0, 1.0],
            0.1,
            301,
            300,
            HANDED_BACK,
            0.0,
            0.0,
        )
    )  # not the person's: left out
    expert = clone_expert(
        tmp_path / DATASET_FILE, tmp_path / "bc", hidden_sizes=(64, 64), steps=1500
    )
    assert expert.meta["num_demonstrations"] == 300
    loaded = load_expert(tmp_path / "bc", obs_dim=4, action_dim=2)
    pred = np.asarray(loaded.act(loaded.params, obs, jax.random.key(0), None))
    err = np.abs(pred - actions)
    assert err.mean() < 0.03 and err.max() < 0.15, (err.mean(), err.max())
    # An untrained actor of the same shape is far off (the test can fail).
    assert np.abs(actions).mean() > 0.3


@pytest.mark.parametrize("task", ["hopper", "walker2d", "ant", "ant_contact", "humanoid"])
def test_every_brax_task_is_drawn_at_its_observed_pose(task) -> None:
    """A state of the task (a C-engine reset, so Brax's own observation of it): the pose the page
    draws is the state's qpos with the root's unobserved x (and y) at 0, the bodies are the
    model's geoms there, and the knobs are named after the actuators' joints."""
    from arld_jax.config import Config
    from arld_jax.envs import make_env
    from arld_jax.human.frames import action_names, body_segments, task_frame, task_model
    from arld_jax.tasks import REGISTRY

    model = task_model(task)
    names = action_names(task)
    assert len(names) == model.nu and all(names) and len(set(names)) == model.nu
    if task in ("hopper", "walker2d"):
        assert names[:3] == ["thigh", "leg", "foot"]
    state = make_env(Config(env_name=task, backend="mujoco")).reset(jax.random.key(0), 1)
    obs, qpos = np.asarray(state.obs[0]), np.asarray(state.inner.pipeline_state.q[0], np.float64)
    pose, vx = REGISTRY[task].pose(obs, model)
    skipped = 2 if task in ("ant", "ant_contact", "humanoid") else 1
    want = qpos.copy()
    want[:skipped] = 0.0
    np.testing.assert_allclose(pose, want, atol=1e-5)
    assert vx == pytest.approx(float(state.inner.pipeline_state.qd[0, 0]), abs=1e-6)
    frame = task_frame(task, obs)
    assert frame["segments"] == body_segments(pose, model)
    assert len(frame["segments"]) == model.ngeom - 1  # every body geom but the floor
    assert frame["rootz"] == pytest.approx(float(state.inner.pipeline_state.x.pos[0, 0, 2]), 1e-4)
    top = max(max(s["z1"], s["z2"]) for s in frame["segments"])
    assert 0.3 < top < frame["top"]  # standing, inside the view
