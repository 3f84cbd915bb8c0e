"""A person as the expert, in the browser (the paper's demonstration UI, appendix A.3).

    python -m arld_jax.run demonstrate --port 8765 --strategy active --uncertainty intrinsic
    (the same as python -m arld_jax.human ...)

starts a page on http://127.0.0.1:8765/ and trains one run in which the expert is whoever sits at
that page. Whenever the query strategy hands control to the expert, the scanned training loop
pauses inside an ordered `io_callback` (`expert.make_human_expert`) until the person has acted for
each of the C steps of the query (or handed the rest back); the actions enter the replay with
is_demo = 1 exactly as a saved expert's would, and every step is written to the run directory's
`demonstrations.jsonl` as it happens (`dataset`). Rerunning the command resumes from the last
checkpoint and replays the demonstrations already given instead of asking again.

The page (web/demonstrate.html, .js) answers the paper's two complaints (A.3, "Cons"):
precise continuous values (a knob per action dimension with ±0.01 / ±0.1 keyboard steps, exact
values typed in, "start from the agent's action", optional smoothing with the previous action),
and the person's time (asked only when the strategy queries; waiting and pausing spend nothing).
It shows the last frames of the HalfCheetah drawn from the simulated pose (`frames`), the agent's
proposed action and its uncertainty, the strategy, the budget left and step k of C.

Modules: `session` (the thread-safe meeting point and the request validation), `server` (Starlette
app, uvicorn thread, 127.0.0.1 only), `expert` (the io_callback expert; behaviour cloning of a
recorded set into a saved expert for `--expert_path`), `dataset`, `frames`, `cli` (the command
line; `cli.run_with_person` trains a run with the person at a `cli.open_session`). This package
imports none of them, so `dataset` and `session` (numpy only) load without JAX.

Every iteration reaches the page through the expert's `observe` hook (`make_observer`), after its
env step, so the frames before a query's first step are the states the agent just visited, a fall
(on tasks whose episodes end, e.g. Hopper) is shown as the state the body fell into, and a pause
holds the run at the next iteration. A hand-back answers with a row of NaNs: the loop cancels the rest of the
query, returns its budget and stores those steps as the agent's (not is_demo).
"""
