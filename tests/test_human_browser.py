"""The demonstration page end to end, in real headless Chromium (Debian's /usr/bin/chromium driven by
the `playwright` package; no browser download).

1. HalfCheetah on MuJoCo's C engine: greedy, C = 2, budget 4. The page shows real cheetah frames; the
   test moves knobs by keyboard and by typing, uses "start from the agent's action", submits, and
   checks that the final TrainState's replay (items with is_demo == 1) and the saved dataset hold
   exactly the actions the page sent, and that the frames are the simulated bodies (the env's
   body positions). Set ARLD_SCREENSHOT=docs/demonstrate.png to save the page during the last query.
2. Toy env: a second tab is refused, takes over explicitly, and hands a query back.
3. Hopper on MuJoCo's C engine (a task whose episodes end): the person drives it into a fall; the
   page announces the fall and draws the fallen state, the demonstration ends with the episode,
   and the next query starts in the new one.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import threading
from pathlib import Path

import jax
import numpy as np
import pytest

from arld_jax.config import Config, tiny
from arld_jax.driver import RunOptions
from arld_jax.human.cli import open_session, run_with_person
from arld_jax.human.dataset import HANDED_BACK, PERSON, read_dataset
from arld_jax.human.server import ServerThread, make_app

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
WAIT_MS = 240_000  # generous: the first query comes after the MJX compile


@pytest.fixture(scope="session")
def chromium() -> str:
    """Debian's Chromium; installed with apt-get when missing and we are root (CI), else skip."""
    if not Path(CHROMIUM).exists():
        if os.geteuid() == 0 and shutil.which("apt-get"):
            env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
            subprocess.run(["apt-get", "update"], check=True, env=env)
            subprocess.run(["apt-get", "install", "-y", "chromium"], check=True, env=env)
        else:
            pytest.skip(f"{CHROMIUM} is missing and apt-get as root is not available to install it")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"installing chromium did not provide {CHROMIUM}")
    return CHROMIUM


@pytest.fixture(scope="session")
def browser(chromium: str):  # noqa: ANN201
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()


class Training:
    """run_with_person in a worker thread, with the page's server on a free port."""

    def __init__(self, cfg: Config, out: Path) -> None:
        self.session = open_session(cfg, out, log=lambda *a: None)
        self.server = ServerThread(make_app(self.session), port=0).start()
        self.result: dict = {}
        self.error: list[BaseException] = []

        def work() -> None:
            try:
                self.result.update(
                    run_with_person(
                        cfg, out, self.session, RunOptions(plots=False, log=lambda *a: None)
                    )
                )
            except BaseException as err:  # noqa: BLE001
                self.error.append(err)

        self.thread = threading.Thread(target=work, daemon=True)
        self.thread.start()

    def finish(self) -> dict:
        self.thread.join(timeout=600)
        self.session.close()
        self.server.stop()
        if self.error:
            raise self.error[0]
        assert self.result.get("complete"), "the run did not finish"
        return self.result


def wait_for_step(page, step_id: int) -> None:  # noqa: ANN001
    page.wait_for_function(
        f"document.body.dataset.stepId === '{step_id}'", timeout=WAIT_MS, polling=100
    )


def send(page, how):  # noqa: ANN001, ANN201
    """Submit (by `how`: a click or the Enter key) and return the action the page sent."""
    with page.expect_response("**/api/action") as resp:
        how()
    response = resp.value
    assert response.ok, response.text()
    return response.request.post_data_json["action"]


def demo_items(state) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """(obs, action) of the replay items marked as demonstrations, in insertion order."""
    size = int(state.replay.size)
    data = jax.tree.map(lambda x: np.asarray(x)[:size], state.replay.data)
    mask = data.is_demo == 1.0
    return data.obs[mask], data.action[mask]


def page_config(**overrides) -> Config:  # noqa: ANN003
    """One run of a Brax task with greedy queries to the person, small enough for a test."""
    base = dict(
        num_envs=1,
        episode_length=100,
        total_env_steps=100,
        learning_starts=50,
        eval_every=50,
        num_eval_episodes=1,
        hidden_sizes=(32, 32),
        batch_size=32,
        replay_capacity=100,
        window_size=10,
        traces_per_eval=5,
        state_sample_size=16,
        strategy="greedy",
    )
    return Config(**(base | overrides))


@pytest.mark.slow
def test_halfcheetah_page_end_to_end(browser, tmp_path: Path) -> None:  # noqa: ANN001
    cfg = page_config(
        backend="mujoco",  # the frames are checked against the simulated bodies below
        total_env_steps=200,
        eval_every=100,
        replay_capacity=200,
        demo_steps=2,
        budget=4,
    )
    training = Training(cfg, tmp_path)
    page = browser.new_page(viewport={"width": 1400, "height": 860})
    page.goto(training.server.url)
    sent, expected = [], []

    # Step 0 (query 0, step 1 of 2): keyboard fine steps and a typed value.
    wait_for_step(page, 0)
    assert "step 1 of 2" in page.inner_text("#step-info")
    assert "greedy" in page.inner_text("#run-info")
    assert "budget left 3 of 4" in page.inner_text("#budget-info")
    assert page.locator("#frames svg line.capsule").count() == 8  # one frame of 8 capsules
    page.focus("#knob-0")
    for key in ["ArrowRight"] * 3 + ["Shift+ArrowRight"] * 2 + ["ArrowLeft"]:
        page.keyboard.press(key)  # +0.03, +0.2, -0.01
    page.fill("#num-1", "-0.37")
    page.focus("#knob-4")
    page.keyboard.press("End")  # +1
    page.keyboard.press("Shift+ArrowLeft")  # 0.9
    expected.append([0.22, -0.37, 0, 0, 0.9, 0])
    sent.append(send(page, lambda: page.click("#submit")))

    # Step 1 (step 2 of 2): start from the agent's action, then adjust one knob.
    wait_for_step(page, 1)
    assert "step 2 of 2" in page.inner_text("#step-info")
    agent = page.evaluate("pending.agent_action")
    page.click("#from-agent")
    page.fill("#num-5", "0.5")
    expected.append([*np.round(agent[:5], 6), 0.5])
    sent.append(send(page, lambda: page.click("#submit")))

    # Step 2 (query 1, step 1 of 2): knobs keep their values; Home on one knob.
    wait_for_step(page, 2)
    assert "query 1, step 1 of 2" in page.inner_text("#step-info")
    page.focus("#knob-2")
    page.keyboard.press("Home")
    page.keyboard.press("ArrowRight")  # -0.99
    expected.append([*expected[-1][:2], -0.99, *expected[-1][3:]])
    sent.append(send(page, lambda: page.click("#submit")))

    # Step 3: four frames; the screenshot; submit with Enter.
    wait_for_step(page, 3)
    assert page.locator("#frames svg").count() == 4
    assert page.locator("#frames svg line.capsule").count() == 4 * 8
    page.fill("#num-3", "0.125")
    expected.append([*expected[-1][:3], 0.125, *expected[-1][4:]])
    shot = os.environ.get("ARLD_SCREENSHOT")
    page.screenshot(path=shot or str(tmp_path / "demonstrate.png"), full_page=True)
    now_frame = page.evaluate(
        "[...document.querySelectorAll('#frames .now line.capsule')].map(l => "
        "[l.dataset.name, +l.getAttribute('x1'), +l.getAttribute('y1'), +l.getAttribute('x2'), "
        "+l.getAttribute('y2')])"
    )
    page.focus("#num-3")
    sent.append(send(page, lambda: page.keyboard.press("Enter")))
    page.close()
    state = training.finish()["state"]

    sent_f32 = np.asarray(sent, np.float32)
    np.testing.assert_allclose(sent_f32, np.asarray(expected, np.float32), atol=2e-6)
    # The replay holds exactly the sent actions as demonstrations, and nothing else.
    demo_obs, demo_action = demo_items(state)
    np.testing.assert_array_equal(demo_action, sent_f32)
    # The dataset too, with the states the person saw.
    header, records = read_dataset(tmp_path / "demonstrations.jsonl")
    assert header["action_names"] == ["bthigh", "bshin", "bfoot", "fthigh", "fshin", "ffoot"]
    assert [(r.query, r.k, r.c, r.env_step, r.source) for r in records] == [
        (0, 1, 2, 0, PERSON),
        (0, 2, 2, 1, PERSON),
        (1, 1, 2, 2, PERSON),
        (1, 2, 2, 3, PERSON),
    ]
    np.testing.assert_array_equal(np.asarray([r.action for r in records], np.float32), sent_f32)
    np.testing.assert_array_equal(np.asarray([r.obs for r in records], np.float32), demo_obs)
    np.testing.assert_allclose(
        np.asarray([r.agent_action for r in records[1:2]]), [agent], atol=1e-6
    )

    # The frames are the simulated bodies: the drawn "now" frame is the kinematics of the
    # recorded state, and the kinematics of an observation put the bodies where the physics had
    # them (the env's state holds every body's position; MJX's agree, tests/test_envs.py).
    from arld_jax.human.frames import halfcheetah_frame, kinematics, qpos_from_obs

    drawn = halfcheetah_frame(np.asarray(records[3].obs))["segments"]
    assert [f[0] for f in now_frame] == [s["name"] for s in drawn]
    np.testing.assert_allclose(
        [f[1:] for f in now_frame], [[s["x1"], s["z1"], s["x2"], s["z2"]] for s in drawn], atol=1e-5
    )
    physics = state.env.inner.pipeline_state
    qpos = np.asarray(physics.q)[0]
    host = kinematics(qpos_from_obs(np.asarray(state.env.obs)[0], x=float(qpos[0])))
    np.testing.assert_allclose(host.xpos[1:], np.asarray(physics.x.pos)[0], atol=1e-4)


def test_second_tab_and_hand_back_on_toy(browser, tmp_path: Path) -> None:  # noqa: ANN001
    cfg = tiny(
        num_envs=1,
        strategy="greedy",
        demo_steps=3,
        budget=3,
        total_env_steps=100,
        learning_starts=50,
        eval_every=50,
        replay_capacity=100,
        window_size=10,
        episode_length=50,
    )
    training = Training(cfg, tmp_path)
    first = browser.new_page()
    first.goto(training.server.url)
    wait_for_step(first, 0)
    assert first.locator("#obs-table tr").count() == 2  # header + the one state seen so far

    second = browser.new_page()
    second.goto(training.server.url)
    second.wait_for_selector("#refusal", state="visible")
    assert "already open in another tab" in second.inner_text("#refusal-text")
    second.click("#takeover")
    wait_for_step(second, 0)
    first.wait_for_selector("#refusal", state="visible")  # the first tab learns it lost the page
    assert "taken over" in first.inner_text("#refusal-text")

    second.fill("#num-0", "0.25")
    second.fill("#num-1", "-0.75")
    sent = send(second, lambda: second.click("#submit"))
    wait_for_step(second, 1)
    with second.expect_response("**/api/hand_back"):
        second.click("#hand-back")
    # The hand-back cancels the rest of query 0 and returns its budget (2 steps): greedy asks
    # again at once, a query of the 2 steps left, answered from the agent's proposal.
    wait_for_step(second, 2)
    second.click("#from-agent")
    later = [send(second, lambda: second.click("#submit"))]
    wait_for_step(second, 3)
    later.append(send(second, lambda: second.click("#submit")))
    state = training.finish()["state"]

    _, records = read_dataset(tmp_path / "demonstrations.jsonl")
    assert [(r.query, r.k, r.c, r.source) for r in records] == [
        (0, 1, 3, PERSON),
        (0, 2, 3, HANDED_BACK),
        (1, 1, 2, PERSON),
        (1, 2, 2, PERSON),
    ]
    # The replay's demonstrations are exactly the submitted actions; the handed-back step is the
    # agent's own (not is_demo), and the budget was spent on the three answered steps only.
    _, demo_action = demo_items(state)
    np.testing.assert_array_equal(demo_action, np.asarray([sent, *later], np.float32))
    np.testing.assert_allclose(later[0], records[2].agent_action, atol=1e-3)


@pytest.mark.slow
def test_hopper_fall_is_shown_and_ends_the_demonstration(browser, tmp_path: Path) -> None:  # noqa: ANN001
    budget, c = 12, 10
    cfg = page_config(env_name="hopper", backend="mujoco", demo_steps=c, budget=budget)
    training = Training(cfg, tmp_path)
    page = browser.new_page(viewport={"width": 1400, "height": 860})
    page.goto(training.server.url)
    wait_for_step(page, 0)
    assert "hopper" in page.inner_text("#run-info")
    assert page.locator("#frames svg line.capsule").count() == 4  # torso, thigh, leg, foot
    assert page.inner_text("#fall-info") == ""
    for i in range(3):  # every joint at full negative torque: Hopper falls within a few steps
        page.focus(f"#knob-{i}")
        page.keyboard.press("Home")
    fell_at = 0
    while True:
        page.focus("#submit")
        send(page, lambda: page.keyboard.press("Enter"))
        fell_at += 1
        wait_for_step(page, fell_at)
        if page.inner_text("#fall-info"):
            break
        assert fell_at < c, "Hopper did not fall under full negative torque"
    # The fall ended the episode and query 0 with it; query 1 starts in the fresh episode.
    assert f"falls 1, the last at env step {fell_at} (env 0)" in page.inner_text("#fall-info")
    assert f"fell at env step {fell_at}" in page.inner_text("#message")
    assert "query 1, step 1 of" in page.inner_text("#step-info")
    fallen = page.locator("#frames .frame.fell")
    assert fallen.count() == 1 and "fell: episode ended" in fallen.inner_text()
    fallen_frame = page.evaluate(
        "[...document.querySelectorAll('#frames .fell line.capsule')].map(l => "
        "[+l.getAttribute('x1'), +l.getAttribute('y1'), +l.getAttribute('x2'), "
        "+l.getAttribute('y2')])"
    )
    page.click("#zero")  # gentle from here on: the rest of the budget in the new episode
    for step in range(fell_at, budget):
        wait_for_step(page, step)
        send(page, lambda: page.click("#submit"))
    page.close()
    state = training.finish()["state"]

    _, records = read_dataset(tmp_path / "demonstrations.jsonl")
    assert [(r.query, r.k, r.c, r.env_step) for r in records] == [
        *((0, k + 1, c, k) for k in range(fell_at)),
        *((1, k + 1, budget - fell_at, fell_at + k) for k in range(budget - fell_at)),
    ]
    # The replay: the last step of query 0 is the fall, stored as terminated; the page drew the
    # state Hopper fell into (the true next observation of that step).
    data = jax.tree.map(lambda x: np.asarray(x)[:budget], state.replay.data)
    assert np.all(data.is_demo == 1.0)
    np.testing.assert_array_equal(np.flatnonzero(data.terminated > 0), [fell_at - 1])

    from arld_jax.human.frames import task_frame

    drawn = task_frame("hopper", data.next_obs[fell_at - 1])["segments"]
    np.testing.assert_allclose(
        fallen_frame, [[s["x1"], s["z1"], s["x2"], s["z2"]] for s in drawn], atol=1e-5
    )
