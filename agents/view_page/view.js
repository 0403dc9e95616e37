// polyswarm view: the merged PolyMap and the robots, live (see agents/view.py).
"use strict";
const NS = "http://www.w3.org/2000/svg";
const svg = document.getElementById("map");
const cellsG = document.getElementById("cells");
const exploredG = document.getElementById("explored");  // below every cell's vectors
const vectorsG = document.getElementById("vectors");
const robotsG = document.getElementById("robots");
const cells = new Map();
let view = null;  // [x, y, w, h] of the viewBox (SVG coordinates: y down)
let fitted = false;

function el(name, attrs, parent) {
  const e = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

function setView(v) { view = v; svg.setAttribute("viewBox", v.join(" ")); }

function fit() {
  const b = cellsG.getBBox();
  if (b.width > 0) { setView([b.x - 1, -(b.y + b.height) - 1, b.width + 2, b.height + 2]); fitted = true; }
}

function drawCell(key, c) {
  let g = cells.get(key);
  if (c === null) { if (g) { g.e.remove(); g.v.remove(); cells.delete(key); } return; }
  if (!g) {
    g = {e: el("g", {"data-cell": key}, exploredG), v: el("g", {"data-cell": key}, vectorsG)};
    cells.set(key, g);
  }
  g.e.replaceChildren();
  g.v.replaceChildren();
  for (const d of c.explored) el("path", {class: "explored", d}, g.e);
  if (c.obstacles) el("path", {class: "obstacles", d: c.obstacles}, g.v);
  if (c.frontiers) el("path", {class: "frontiers", d: c.frontiers}, g.v);
}

function onCells(m) {
  if (m.full) for (const key of [...cells.keys()]) if (!(key in m.cells)) drawCell(key, null);
  for (const [key, c] of Object.entries(m.cells)) drawCell(key, c);
  svg.dataset.version = m.ver;
  svg.dataset.polygons = m.polygons;
  if (!fitted) fit();
  requestAnimationFrame(() => send({t: "shown", ver: m.ver, at_ms: Date.now()}));
}

function points(list) { return list.map(p => p[0] + "," + p[1]).join(" "); }

function drawRobot(id, r, radius) {
  let g = document.getElementById("robot-" + id);
  if (!g) g = el("g", {id: "robot-" + id, class: "robot"}, robotsG);
  g.classList.toggle("lost", !r.alive);
  g.dataset.state = r.state;
  g.dataset.x = r.x; g.dataset.y = r.y;
  g.replaceChildren();
  if (r.trail.length > 1) el("polyline", {class: "trail", points: points(r.trail)}, g);
  if (r.frontier.length > 1) el("polyline", {class: "frontier", points: points(r.frontier)}, g);
  if (r.path.length > 1) el("polyline", {class: "path", points: points(r.path)}, g);
  if (r.goal) {
    const [gx, gy] = r.goal, s = 0.2;
    el("path", {class: "goal", d: `M${gx - s} ${gy - s}L${gx + s} ${gy + s}M${gx - s} ${gy + s}L${gx + s} ${gy - s}`}, g);
  }
  if (!r.seen) return;
  el("circle", {class: "body", cx: r.x, cy: r.y, r: radius}, g);
  el("line", {class: "body", x1: r.x, y1: r.y, x2: r.x + radius * Math.cos(r.th), y2: r.y + radius * Math.sin(r.th)}, g);
  const t = el("text", {transform: `translate(${r.x + radius * 1.2},${r.y}) scale(1,-1)`}, g);
  t.textContent = `${id} ${r.state}`;
}

function drawTargets(targets, blacklisted) {
  const g = document.getElementById("targets");
  g.replaceChildren();
  for (const [x, y] of targets) el("circle", {class: "target", cx: x, cy: y, r: 0.15}, g);
  const s = 0.15;
  for (const [x, y] of blacklisted) {
    el("path", {class: "blacklisted", d: `M${x - s} ${y - s}L${x + s} ${y + s}M${x - s} ${y + s}L${x + s} ${y - s}`}, g);
  }
}

function onState(m) {
  drawTargets(m.targets, m.blacklisted);
  for (const [id, r] of Object.entries(m.robots)) drawRobot(id, r, m.radius);
  const when = m.simulated ? `simulated ${m.time_s.toFixed(0)} s` : `${m.time_s.toFixed(0)} s`;
  document.getElementById("mission").textContent = `mission ${m.mission}, ${when}, map v${m.ver}`;
  const body = document.querySelector("#fleet tbody");
  body.replaceChildren();
  for (const [id, r] of Object.entries(m.robots)) {
    const tr = document.createElement("tr");
    tr.className = r.alive ? "" : "lost";
    for (const v of [id, r.state, (r.bytes / 1000).toFixed(1) + " kB"]) {
      const td = document.createElement("td"); td.textContent = v; tr.appendChild(td);
    }
    body.appendChild(tr);
  }
  const c = m.curve;
  if (c.length > 1) {
    const t1 = c[c.length - 1][0] || 1, a1 = Math.max(...c.map(p => p[1])) || 1;
    document.getElementById("curve-line").setAttribute("points",
      c.map(([t, a]) => `${(100 * t / t1).toFixed(2)},${(60 - 58 * a / a1).toFixed(2)}`).join(" "));
    document.getElementById("curve-label").textContent = `${c[c.length - 1][1].toFixed(0)} m² explored`;
  }
}

// --- pan and zoom --------------------------------------------------------------------
function toSvg(ev) {
  const r = svg.getBoundingClientRect();
  return [view[0] + (ev.clientX - r.left) / r.width * view[2], view[1] + (ev.clientY - r.top) / r.height * view[3]];
}
svg.addEventListener("wheel", ev => {
  if (!view) return;
  ev.preventDefault();
  const k = ev.deltaY > 0 ? 1.2 : 1 / 1.2, [px, py] = toSvg(ev);
  setView([px - (px - view[0]) * k, py - (py - view[1]) * k, view[2] * k, view[3] * k]);
}, {passive: false});
let drag = null;
svg.addEventListener("mousedown", ev => { if (view) drag = toSvg(ev); });
window.addEventListener("mouseup", () => { drag = null; });
svg.addEventListener("mousemove", ev => {
  if (!drag) return;
  const [px, py] = toSvg(ev);
  setView([view[0] + drag[0] - px, view[1] + drag[1] - py, view[2], view[3]]);
});
svg.addEventListener("dblclick", fit);

// --- the connection, re-opened when it drops ------------------------------------------
let socket = null;
function send(m) { if (socket && socket.readyState === 1) socket.send(JSON.stringify(m)); }
function connect() {
  socket = new WebSocket(`ws://${location.host}/ws`);
  socket.onmessage = ev => {
    const m = JSON.parse(ev.data);
    if (m.t === "cells") onCells(m); else if (m.t === "state") onState(m);
  };
  socket.onopen = () => { document.body.dataset.connected = "1"; };
  socket.onclose = () => { document.body.dataset.connected = "0"; setTimeout(connect, 1000); };
}
connect();
