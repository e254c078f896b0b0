// ncfmu serve --web: the live page. Plain JS, nothing from outside: the machine is described once
// (/api/machine), then frames of what changed arrive as server-sent events (/api/events).
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const values = {};          // INSTANCE.VAR -> value, and Simulation.* (what the frames said)
let machine = null;
let forced = new Set();
let section = null;         // the part section's SVG elements
let lastState = "";
const seenAlarms = {};
let crashesShown = 0;

function el(tag, attrs, text) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}

function svg(tag, attrs) {
  const e = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  return e;
}

function format(name, value) {
  if (value === undefined || value === null) return "-";
  if (typeof value === "boolean") return value ? "on" : "off";
  if (typeof value === "number") {
    if (name === "Simulation.lag") return (value * 1e3).toFixed(2);
    if (name === "Simulation.time") return value.toFixed(3);
    const p = machine && machine.points[name];
    if (p && p.type === "Integer") return String(value);
    if (p && p.unit === "rev/min") return value.toFixed(0);
    if (name.endsWith(".feed_override")) return (value * 100).toFixed(0) + " %";
    if (Number.isInteger(value) && !(p && p.type === "Real")) return String(value);
    return value.toFixed(3);
  }
  if (Array.isArray(value)) return value.join(", ");
  return String(value);
}

function cell(name, tag) {
  const e = el(tag || "td", {"data-var": name}, "-");
  const p = machine.points[name];
  if (p) e.title = `${name}${p.unit ? " [" + p.unit + "]" : ""}: ${p.description}`;
  return e;
}

function build() {
  document.getElementById("system").textContent = "ncfmu " + machine.system;
  document.title = "ncfmu " + machine.system;
  const axes = document.getElementById("axes");
  axes.parentElement.classList.add("dro");
  for (const a of machine.axes) {
    const row = el("tr");
    row.append(el("td", {}, a), cell(a + ".pos"), cell(a + ".pos_cmd"),
               machine.points[a + ".following_error"] ? cell(a + ".following_error") : el("td", {}, ""));
    axes.append(row);
  }
  const spindles = document.getElementById("spindles");
  for (const s of machine.spindles) {
    const row = el("tr");
    row.append(el("td", {}, s + " rev/min"), cell(s + ".speed"), el("td", {}, "cmd"), cell(s + ".speed_cmd"));
    spindles.append(row);
  }
  const controllers = document.getElementById("controllers");
  for (const c of machine.controllers) {
    for (const v of c.values) {
      const row = el("tr");
      row.append(el("td", {}, `${c.name}.${v}`), cell(`${c.name}.${v}`));
      controllers.append(row);
    }
    const p = machine.points[c.name + ".feed_override"];
    const dial = document.getElementById("override");
    if (p && p.max !== null) dial.max = String(Math.round(p.max * 100));
    if (p && p.min !== null) dial.min = String(Math.round(p.min * 100));
  }
  if (machine.section) buildSection(machine.section);
  else document.getElementById("section-view").hidden = true;     // a grinder: no section is cut
}

function ringsPath(rings) {
  return rings.map(r => "M" + r.map(([u, v]) => `${u},${v}`).join("L") + "Z").join("");
}

function buildSection(s) {
  const view = document.getElementById("part");
  let umin = Infinity, umax = -Infinity, vmin = Infinity, vmax = -Infinity;
  for (const r of [...s.stock, ...s.programmed]) for (const [u, v] of r) {
    umin = Math.min(umin, u); umax = Math.max(umax, u); vmin = Math.min(vmin, v); vmax = Math.max(vmax, v);
  }
  const mu = 0.25 * (umax - umin) + 2, mv = 0.25 * (vmax - vmin) + 2;
  umin -= mu; umax += mu; vmin -= mv; vmax += mv;
  if (s.lathe) vmin = Math.min(vmin, -mv);
  // v up: the group flips the plane, so the view box's y runs from -vmax to -vmin
  view.setAttribute("viewBox", `${umin} ${-vmax} ${umax - umin} ${vmax - vmin}`);
  const g = svg("g", {transform: "scale(1,-1)"});
  if (s.lathe) g.append(svg("line", {class: "axis", x1: umin, y1: 0, x2: umax, y2: 0}));   // the spindle's axis
  const stock = svg("path", {class: "stock", d: ringsPath(s.stock), "fill-rule": "evenodd"});
  const made = svg("path", {class: "made", d: ringsPath(s.stock), "data-section": "made"});
  const programmed = svg("path", {class: "programmed", d: ringsPath(s.programmed), "data-section": "programmed"});
  const tool = svg("polygon", {class: "tool", "data-section": "tool"});
  const crashes = svg("g", {"data-section": "crashes"});
  // where the tool is, at a size the view shows however small the tool (the seed mill's cutter is 0.4 mm)
  const mark = svg("circle", {class: "tool-mark", r: 0.015 * (umax - umin), "data-section": "tool-mark"});
  g.append(stock, made, programmed, crashes, tool, mark);
  view.append(g);
  document.getElementById("plane").textContent =
    `${s.axes[0]} (${s.u}) across, ${s.axes[1]} (${s.v}) up; grey: the stock, dark: the part so far, ` +
    "blue: the programmed part, orange: the tool";
  section = {made, tool, mark, crashes, spec: s};
}

function drawTool() {
  if (!section) return;
  const s = section.spec;
  const u = values[s.u], v = values[s.v];
  if (typeof u !== "number" || typeof v !== "number") return;
  const number = s.tool ? String(values[s.tool] || 0) : "0";
  const outline = s.tools[number] || s.tools["0"];
  let pts = outline.map(([a, b]) => `${u + a},${v + b}`);
  if (outline.length < 3) {       // a segment: drawn as a thin sliver around it
    pts = [...pts, ...outline.slice().reverse().map(([a, b]) => `${u + a + 0.2},${v + b + 0.2}`)];
  }
  section.tool.setAttribute("points", pts.join(" "));
  section.mark.setAttribute("cx", u);
  section.mark.setAttribute("cy", v);
}

function drawSection(frameSection) {
  if (!section || !frameSection) return;
  section.made.setAttribute("d", ringsPath(frameSection.stock));
  section.crashes.replaceChildren(...(frameSection.crashes || []).filter(c => c.at).map(c =>
    svg("circle", {class: "crash", cx: c.at[0], cy: c.at[1], r: 0.8})));
}

function showProgram() {
  const list = document.getElementById("program");
  const c = machine.controllers.find(c => c.program);
  if (!c) return;
  const text = values[c.program];
  if (typeof text !== "string" || list.dataset.text === text) return;
  list.dataset.text = text;
  const lines = text.trim() ? text.split(/\r?\n/) : [];       // no program: the seed's own cycle
  list.replaceChildren(...lines.map((line, i) => el("li", {"data-line": String(i + 1)}, line || " ")));
}

function markLine() {
  for (const c of machine.controllers) {
    if (!c.line) continue;
    const n = values[c.line];
    const list = document.getElementById("program");
    const old = list.querySelector("li.current");
    const now = list.querySelector(`li[data-line="${n}"]`);
    if (old === now) continue;
    if (old) old.classList.remove("current");
    if (now) {
      now.classList.add("current");
      const top = now.offsetTop - list.offsetTop, h = list.clientHeight;
      if (top < list.scrollTop || top > list.scrollTop + h - 20) list.scrollTop = Math.max(0, top - h / 3);
    }
  }
}

function event(text) {
  const list = document.getElementById("events");
  list.prepend(el("li", {class: "event"}, `t = ${format("Simulation.time", values["Simulation.time"])} s: ${text}`));
}

function apply(frame) {
  for (const [k, v] of Object.entries(frame.values || {})) values[k] = v;
  for (const k of ["time", "state", "reason", "lag", "overruns", "verdict"]) {
    if (k in frame) values["Simulation." + k] = frame[k];
  }
  if ("forced" in frame) { values["Simulation.forced"] = frame.forced; forced = new Set(frame.forced); }
  if ("crashes" in frame) {
    values["Simulation.crashes"] = frame.crashes.length;
    values["Simulation.crash"] = frame.crashes.length ? frame.crashes[frame.crashes.length - 1].text : "";
    if (frame.crashes.length < crashesShown) crashesShown = 0;         // a Reset
    for (const c of frame.crashes.slice(crashesShown)) event(c.text);
    crashesShown = frame.crashes.length;
  }
  const vel = machine.axes.map(a => values[a + ".vel"]).filter(v => typeof v === "number");
  if (vel.length) values["Simulation.feed"] = 60 * Math.hypot(...vel);
  for (const [name, value] of Object.entries(values)) {
    if (name.endsWith(".alarm") && typeof value === "boolean") {
      if (value && !seenAlarms[name]) event(`${name} raised`);
      seenAlarms[name] = value;
    }
  }
  const state = values["Simulation.state"];
  if (state !== lastState) {
    if (["crashed", "failed", "faulted", "held"].includes(state)) event(`${state}: ${values["Simulation.reason"]}`);
    lastState = state;
  }
  for (const e of document.querySelectorAll("[data-var]")) {
    const name = e.dataset.var;
    const text = format(name, values[name]);
    if (e.textContent !== text) e.textContent = text;
    e.classList.toggle("forced", forced.has(name));
  }
  const st = document.querySelector('[data-var="Simulation.state"]');
  st.className = "state " + (state || "");
  showProgram();
  markLine();
  drawSection(frame.section);
  drawTool();
}

async function act(what, body) {
  const said = document.getElementById("refusal");
  const response = await fetch("/api/action/" + what, {
    method: "POST", headers: {"Content-Type": "application/json"}, body: JSON.stringify(body || {})});
  const answer = await response.json();
  said.textContent = response.ok ? "" : `${what}: ${answer.error}`;
}

async function main() {
  machine = await (await fetch("/api/machine")).json();
  build();
  for (const b of document.querySelectorAll("button[data-action]")) {
    b.addEventListener("click", () => act(b.dataset.action));
  }
  const dial = document.getElementById("override");
  dial.addEventListener("input", () => { document.getElementById("override-dial").textContent = dial.value + " %"; });
  dial.addEventListener("change", () => act("override", {value: Number(dial.value) / 100}));
  const link = document.getElementById("link");
  const source = new EventSource("/api/events");
  source.onopen = () => { link.textContent = "live"; };
  source.onerror = () => { link.textContent = "disconnected"; };
  source.onmessage = (m) => {
    apply(JSON.parse(m.data));
    document.body.dataset.frames = String(Number(document.body.dataset.frames || 0) + 1);
  };
}

main();
