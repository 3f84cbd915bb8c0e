// The demonstration page (paper A.3, Fig. 10): the last states, the agent's proposal and its
// uncertainty, one knob per action dimension with fine keyboard steps, and submit / hand back.
"use strict";

const TOKEN_HEADER = "X-Demo-Session";
const POLL_MS = 300;
let token = null;
let run = null;
let knobs = [];          // the knob values: the source of truth (ranges and boxes display them)
let pending = null;      // the pending step shown, or null
let lastSent = null;     // the last action this page sent (for smoothing)
let polling = null;
let sending = false;
let fallsSeen = 0;        // falls already announced

const $ = (id) => document.getElementById(id);
const round6 = (v) => Math.round(v * 1e6) / 1e6;
const clip = (v) => Math.max(-1, Math.min(1, v));
const fmt = (v, d = 3) => (v >= 0 ? "+" : "") + v.toFixed(d);
const fmtVec = (xs, d = 3) => "[" + xs.map((v) => fmt(v, d)).join(", ") + "]";

function message(text, kind) {
  const el = $("message");
  el.textContent = text;
  el.className = kind || "";
}

async function api(method, path, body) {
  const headers = { "Content-Type": "application/json" };
  if (token) headers[TOKEN_HEADER] = token;
  const init = { method, headers };
  if (body !== undefined) init.body = JSON.stringify(body);
  let resp;
  try {
    resp = await fetch(path, init);
  } catch (err) {
    return { ok: false, status: 0, data: { error: "the training process is not reachable (" + err + ")" } };
  }
  let data;
  try { data = await resp.json(); } catch (err) { data = { error: "HTTP " + resp.status }; }
  return { ok: resp.ok, status: resp.status, data };
}

function errorText(data) {
  return data.error + (data.allowed ? " (allowed: " + data.allowed + ")" : "");
}

// ------------------------------------------------------------------ session

async function register(takeOver) {
  const r = await api("POST", "/api/session", takeOver ? { take_over: true } : {});
  if (r.ok) {
    token = r.data.token;
    $("refusal").style.display = "none";
    $("main").style.display = "";
    if (!polling) polling = setInterval(poll, POLL_MS);
    poll();
  } else {
    refuse(errorText(r.data));
  }
}

function refuse(text) {
  $("main").style.display = "none";
  $("refusal").style.display = "block";
  $("refusal-text").textContent = text;
  $("status").textContent = "not this tab";
  $("status").className = "badge error";
}

// ------------------------------------------------------------------ knobs

function buildKnobs() {
  const box = $("knobs");
  box.innerHTML = "";
  knobs = run.action_names.map(() => 0);
  run.action_names.forEach((name, i) => {
    const row = document.createElement("div");
    row.className = "knob";
    row.innerHTML =
      `<label for="knob-${i}">${name}</label>` +
      `<input id="knob-${i}" type="range" min="-1" max="1" step="any" value="0" aria-label="${name}">` +
      `<input id="num-${i}" type="number" min="-1" max="1" step="0.01" value="0.00" aria-label="${name} value">` +
      `<span class="agentval" id="agent-${i}" title="the agent's proposal">-</span>`;
    box.appendChild(row);
    const range = row.querySelector(`#knob-${i}`);
    const num = row.querySelector(`#num-${i}`);
    range.addEventListener("input", () => setKnob(i, Math.round(parseFloat(range.value) * 1000) / 1000, "range"));
    range.addEventListener("keydown", (ev) => knobKey(ev, i));
    num.addEventListener("input", () => {
      const v = parseFloat(num.value);
      if (num.value.trim() === "" || !Number.isFinite(v) || v < -1 || v > 1) {
        num.style.background = "#fbb";
        message(`${name}: type a number in [-1, 1]`, "err");
        return;
      }
      num.style.background = "";
      setKnob(i, v, "num");
    });
  });
}

function knobKey(ev, i) {
  const step = ev.shiftKey ? 0.1 : 0.01;
  let v = null;
  if (ev.key === "ArrowRight" || ev.key === "ArrowUp") v = knobs[i] + step;
  else if (ev.key === "ArrowLeft" || ev.key === "ArrowDown") v = knobs[i] - step;
  else if (ev.key === "PageUp") v = knobs[i] + 0.1;
  else if (ev.key === "PageDown") v = knobs[i] - 0.1;
  else if (ev.key === "Home") v = -1;
  else if (ev.key === "End") v = 1;
  if (v === null) return;
  ev.preventDefault();
  setKnob(i, v);
}

function setKnob(i, v, from) {
  v = clip(round6(v));
  knobs[i] = v;
  if (from !== "range") $(`knob-${i}`).value = String(v);
  if (from !== "num") { $(`num-${i}`).value = String(v); $(`num-${i}`).style.background = ""; }
  updatePreview();
}

function smoothing() { return parseFloat($("smoothing").value); }

function actionToSend() {
  const lam = smoothing();
  if (lam <= 0 || lastSent === null) return knobs.map(round6);
  return knobs.map((v, i) => clip(round6(lam * lastSent[i] + (1 - lam) * v)));
}

function updatePreview() {
  const lam = smoothing();
  $("smoothing-val").textContent = lam > 0 ? lam.toFixed(2) : "off";
  $("preview").textContent = fmtVec(actionToSend());
}

// ------------------------------------------------------------------ drawing

const SVG_NS = "http://www.w3.org/2000/svg";
function colour(name) {
  if (run.env_name === "halfcheetah") {  // back and front legs
    if (name.startsWith("b")) return "#2a6fb0";
    if (name.startsWith("f")) return "#d9822b";
  } else if (name.includes("left")) {
    return "#2a6fb0";
  } else if (name.includes("right")) {
    return "#d9822b";
  }
  return "#3b3b3b";
}

function bodySvg(frame) {
  const top = frame.top || 1.35;  // metres shown above the ground (HalfCheetah: 1.35)
  const svg = document.createElementNS(SVG_NS, "svg");
  svg.setAttribute("viewBox", `-1.35 ${-top} 2.7 ${top + 0.25}`);  // x in [-1.35, 1.35], z in [-0.25, top]
  svg.setAttribute("class", "frame-svg");
  const g = document.createElementNS(SVG_NS, "g");
  g.setAttribute("transform", "scale(1,-1)");  // z up
  const ground = document.createElementNS(SVG_NS, "rect");
  ground.setAttribute("x", -1.35); ground.setAttribute("y", -0.25);
  ground.setAttribute("width", 2.7); ground.setAttribute("height", 0.25);
  ground.setAttribute("fill", "#c8c2b4");
  g.appendChild(ground);
  for (const s of frame.segments) {
    const line = document.createElementNS(SVG_NS, "line");
    line.setAttribute("x1", s.x1); line.setAttribute("y1", s.z1);
    line.setAttribute("x2", s.x2); line.setAttribute("y2", s.z2);
    line.setAttribute("stroke", colour(s.name));
    line.setAttribute("stroke-width", 2 * s.r);
    line.setAttribute("stroke-linecap", "round");
    line.setAttribute("class", "capsule");
    line.dataset.name = s.name;
    g.appendChild(line);
  }
  svg.appendChild(g);
  return svg;
}

function renderFrames(p) {
  const box = $("frames");
  box.innerHTML = "";
  $("obs-view").innerHTML = "";
  const frames = p ? p.frames : [];
  if (frames.length && frames[0].segments) {
    $("frames-title").textContent = `Last ${frames.length} state(s) of env ${p ? p.env : "-"}, oldest first (side view, centred on the torso)`;
    frames.forEach((f, j) => {
      const div = document.createElement("div");
      div.className = "frame" + (j === frames.length - 1 ? " now" : "") + (f.fell ? " fell" : "");
      div.appendChild(bodySvg(f));
      const label = document.createElement("div");
      const ago = frames.length - 1 - j;
      const when = f.fell ? "fell: episode ended" : (ago === 0 ? "now" : `t-${ago}`);
      label.textContent = when + ` (step ${f.env_step}, vx ${f.vx.toFixed(2)})`;
      div.appendChild(label);
      box.appendChild(div);
    });
  } else {
    $("frames-title").textContent = `Last ${frames.length} observation(s), oldest first`;
    const table = document.createElement("table");
    table.className = "obs";
    table.id = "obs-table";
    const head = "<tr><th>env step</th>" + (frames[0] ? frames[0].obs.map((_, i) => `<th>obs[${i}]</th>`).join("") : "") + "</tr>";
    table.innerHTML = head + frames.map((f) =>
      `<tr${f.fell ? ' class="fell" title="fell: the episode ended here"' : ""}><td>${f.env_step}${f.fell ? " (fell)" : ""}</td>${f.obs.map((v) => `<td>${fmt(v)}</td>`).join("")}</tr>`).join("");
    $("obs-view").appendChild(table);
  }
}

// ------------------------------------------------------------------ state

function renderHeader(s) {
  const badge = $("status");
  badge.textContent = s.status === "waiting" ? "waiting for you" : s.status;
  badge.className = "badge " + s.status;
  const r = s.run;
  const rule = r.strategy === "active" ? ` t_query ${r.t_query}` : r.strategy === "bernoulli" ? ` b ${r.query_prob}` : "";
  $("run-info").textContent = `strategy ${r.strategy}${rule}, u(s) ${r.uncertainty}, C ${r.demo_steps}, ${r.env_name}`;
  const used = s.pending ? s.pending.demos_used : (s.progress.demos_used ?? 0);
  $("budget-info").textContent = `budget left ${r.budget - used} of ${r.budget}`;
  const step = s.pending ? s.pending.env_step : (s.progress.env_step ?? 0);
  $("progress-info").textContent = `env step ${step} / ${r.total_env_steps}, ${s.recorded} recorded`;
  $("pause").textContent = s.paused ? "Resume" : "Pause";
  $("last-submitted").textContent = s.last_submitted ? fmtVec(s.last_submitted) : "-";
  renderFalls(s);
  document.body.dataset.status = s.status;
}

// A fall ends the episode (the task's health rule): the env restarts from a fresh state and a
// demonstration in progress there ends with it.
function renderFalls(s) {
  if (!s.falls) { $("fall-info").textContent = ""; return; }
  const last = s.last_fall;
  $("fall-info").textContent = `falls ${s.falls}, the last at env step ${last.env_step} (env ${last.env})`;
  if (s.falls > fallsSeen) {
    fallsSeen = s.falls;
    message(`env ${last.env} fell at env step ${last.env_step}: its episode ended and a new one began`, "err");
  }
}

function renderPending(p) {
  pending = p;
  document.body.dataset.stepId = p ? String(p.step_id) : "";
  $("submit").disabled = !p;
  $("hand-back").disabled = !p;
  $("from-agent").disabled = !p;
  if (!p) {
    $("step-info").textContent = "(no query pending: the agent is in control)";
    return;
  }
  $("step-info").textContent = `query ${p.query}, step ${p.k} of ${p.c} (env ${p.env}, env step ${p.env_step})`;
  $("agent-action").textContent = fmtVec(p.agent_action);
  $("uncertainty").textContent = p.uncertainty.toPrecision(4);
  $("budget-left").textContent = `${p.budget_left} (after this step)`;
  p.agent_action.forEach((v, i) => { $(`agent-${i}`).textContent = fmt(v, 2); });
  renderFrames(p);
}

async function poll() {
  const r = await api("GET", "/api/state");
  if (!r.ok) {
    if (r.status === 403 || r.status === 401) {
      clearInterval(polling); polling = null;
      refuse(errorText(r.data));
    } else {
      message(errorText(r.data), "err");
    }
    return;
  }
  const s = r.data;
  if (!run) { run = s.run; buildKnobs(); updatePreview(); }
  renderHeader(s);
  const id = s.pending ? s.pending.step_id : null;
  const shown = pending ? pending.step_id : null;
  if (id !== shown) renderPending(s.pending);
}

// ------------------------------------------------------------------ actions

async function submit() {
  if (!pending || sending) return;
  sending = true;
  const action = actionToSend();
  const r = await api("POST", "/api/action", { step_id: pending.step_id, action });
  sending = false;
  if (r.ok) {
    lastSent = action;
    message(`recorded: query ${r.data.recorded.query}, step ${r.data.recorded.k} of ${r.data.recorded.c}`, "ok");
    renderPending(null);
    updatePreview();
  } else {
    message(errorText(r.data), "err");
  }
  poll();
}

async function handBack() {
  if (!pending) return;
  const r = await api("POST", "/api/hand_back", { step_id: pending.step_id });
  if (r.ok) { message("handed back: the agent acts for the rest of this query", "ok"); renderPending(null); }
  else message(errorText(r.data), "err");
  poll();
}

function fromAgent() {
  if (!pending) return;
  pending.agent_action.forEach((v, i) => setKnob(i, v));
}

async function togglePause() {
  const paused = $("pause").textContent === "Pause";
  const r = await api("POST", "/api/pause", { paused });
  if (!r.ok) message(errorText(r.data), "err");
  poll();
}

$("submit").addEventListener("click", submit);
$("hand-back").addEventListener("click", handBack);
$("from-agent").addEventListener("click", fromAgent);
$("zero").addEventListener("click", () => knobs.forEach((_, i) => setKnob(i, 0)));
$("pause").addEventListener("click", togglePause);
$("smoothing").addEventListener("input", updatePreview);
$("takeover").addEventListener("click", () => register(true));
document.addEventListener("keydown", (ev) => {
  const typing = ev.target && ev.target.type === "number";
  if (ev.key === "Enter" && !(ev.target && ev.target.tagName === "BUTTON")) { ev.preventDefault(); submit(); }
  else if ((ev.key === "a" || ev.key === "A") && !typing) fromAgent();
});
register(false);
