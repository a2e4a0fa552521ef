// imubench live view: one card per station/sensor, fed by server-sent events from
// /events (event types: broker, sensor, remove). Plots use uPlot (vendor/, MIT).
"use strict";

const GROUPS = [["gyro", ["gx", "gy", "gz"]], ["accel", ["ax", "ay", "az"]]];
const COLORS = { gx: "#d62728", gy: "#2ca02c", gz: "#1f77b4",
                 ax: "#d62728", ay: "#2ca02c", az: "#1f77b4" };
const cards = new Map();   // key -> card
const main = document.getElementById("sensors");

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v; else node.setAttribute(k, v);
  }
  for (const c of children) node.append(c);
  return node;
}

function fmtNumber(v, unit) {
  if (v === null || v === undefined) return "-";
  if (typeof v !== "number") return typeof v === "object" ? JSON.stringify(v) : String(v);
  if (unit === "B") {
    const units = ["B", "kB", "MB", "GB", "TB"];
    let i = 0; let x = v;
    while (x >= 1000 && i < units.length - 1) { x /= 1000; i++; }
    return `${x.toPrecision(4)} ${units[i]}`;
  }
  const text = Number.isInteger(v) ? String(v) : v.toPrecision(5);
  return unit ? `${text} ${unit}` : text;
}

function withAlpha(hex, alpha) {
  return hex + Math.round(alpha * 255).toString(16).padStart(2, "0");
}

function plotData(curves, chans) {
  const taus = new Set();
  for (const ch of chans) {
    const c = curves[ch];
    if (!c) continue;
    c.tau_s.forEach((t, i) => { if (t > 0 && c.dev[i] > 0) taus.add(t); });
  }
  const x = [...taus].sort((a, b) => a - b);
  const at = new Map(x.map((t, i) => [t, i]));
  const data = [x];
  for (const ch of chans) {
    const dev = new Array(x.length).fill(null);
    const lo = new Array(x.length).fill(null);
    const hi = new Array(x.length).fill(null);
    const c = curves[ch];
    if (c) {
      c.tau_s.forEach((t, i) => {
        const j = at.get(t);
        if (j === undefined) return;
        dev[j] = c.dev[i];
        lo[j] = c.ci_low[i] > 0 ? c.ci_low[i] : null;
        hi[j] = c.ci_high[i] > 0 ? c.ci_high[i] : null;
      });
    }
    data.push(dev, lo, hi);
  }
  return data;
}

function tickLabels(u, splits) {
  return splits.map((v) => {
    if (v === null || v === undefined) return null;
    return v >= 0.001 && v < 10000 ? String(+v.toPrecision(3)) : v.toExponential(0);
  });
}

function plotOptions(title, units, chans, width) {
  const series = [{ label: "tau_s" }];
  const bands = [];
  chans.forEach((ch, k) => {
    const col = COLORS[ch] || "#444";
    series.push({ label: ch, stroke: col, width: 2, spanGaps: true,
                  points: { show: true, size: 5 } });
    series.push({ label: `${ch} low`, stroke: withAlpha(col, 0.35), width: 1,
                  spanGaps: true, points: { show: false } });
    series.push({ label: `${ch} high`, stroke: withAlpha(col, 0.35), width: 1,
                  spanGaps: true, points: { show: false } });
    bands.push({ series: [3 * k + 3, 3 * k + 2], fill: withAlpha(col, 0.15) });
  });
  return {
    title, width, height: 260, legend: { show: false }, series, bands,
    scales: { x: { time: false, distr: 3, log: 10 }, y: { distr: 3, log: 10 } },
    axes: [{ label: "tau (s)", values: tickLabels },
           { label: `deviation (${units})`, size: 72, values: tickLabels }],
    cursor: { drag: { x: false, y: false } },
  };
}

function makeCard(view) {
  const card = { key: view.key, plots: {}, plotStat: {}, stat: null, view: null,
                 receivedAt: 0 };
  const state = el("span", { class: "state" });
  const meta = el("span", { class: "meta" });
  const select = el("select", { class: "stat", title: "statistic shown" });
  select.addEventListener("change", () => { card.stat = select.value; render(card); });
  const plots = el("div", { class: "plots" });
  for (const [group] of GROUPS) plots.append(el("div", { class: "plot", "data-group": group }));
  const legend = el("div", { class: "legend" });
  for (const [, chans] of GROUPS) {
    for (const ch of chans) {
      legend.append(el("span", {}, el("i", { style: `background:${COLORS[ch]}` }), ch));
    }
  }
  const root = el("section", { class: "sensor", "data-key": view.key,
                               "data-station": view.station, "data-sensor": view.sensor,
                               "data-points": "0", "data-state": "" },
    el("h2", {}, el("span", { class: "name" }, `${view.station} / ${view.sensor}`), state,
       meta, select),
    el("div", { class: "plots-wrap" }, plots, legend),
    el("div", { class: "tables" },
       el("table", { class: "health" }),
       el("div", { class: "analysis" }, el("table", { class: "readouts" }),
          el("div", { class: "jig" }), el("table", { class: "extra" }))),
    el("div", { class: "errors" }));
  card.root = root; card.stateEl = state; card.metaEl = meta; card.select = select;
  const after = [...cards.keys()].sort().find((k) => k > view.key);
  main.insertBefore(root, after ? cards.get(after).root : null);
  cards.set(view.key, card);
  document.getElementById("empty").hidden = true;
  return card;
}

function renderPlots(card) {
  const view = card.view;
  const curves = (view.statistics || {})[card.stat] || {};
  let points = 0;
  for (const [group, chans] of GROUPS) {
    const present = chans.filter((ch) => curves[ch]);
    const holder = card.root.querySelector(`.plot[data-group="${group}"]`);
    if (!present.length) { holder.hidden = true; continue; }
    holder.hidden = false;
    const data = plotData(curves, present);
    for (let k = 0; k < present.length; k++) {
      points += data[1 + 3 * k].filter((v) => v !== null).length;
    }
    const units = curves[present[0]].units || "";
    const key = `${card.stat}|${present.join(",")}`;
    let u = card.plots[group];
    if (u && card.plotStat[group] !== key) { u.destroy(); u = null; }
    if (!data[0].length) { if (u) { u.destroy(); card.plots[group] = null; } continue; }
    if (!u) {
      const width = Math.max(280, Math.floor(holder.clientWidth || 420));
      u = new uPlot(plotOptions(`${card.stat.toUpperCase()} ${group}`, units, present, width),
                    data, holder);
      card.plots[group] = u; card.plotStat[group] = key;
    } else {
      u.setData(data);
    }
  }
  card.root.dataset.points = String(points);
}

function renderHealth(card) {
  const view = card.view;
  const table = card.root.querySelector("table.health");
  table.replaceChildren();
  const row = (label, value, cls) => table.append(
    el("tr", cls ? { class: cls } : {}, el("th", {}, label), el("td", {}, value)));
  row("state", view.state + (view.status_state && view.status_state !== view.state
                             ? ` (status: ${view.status_state})` : ""));
  const link = view.status_state === null ? "no retained status seen"
    : view.status_state === "offline"
      ? `disconnected${view.offline_at ? " (seen offline by this view at " + view.offline_at + ")" : ""}`
      : "connected (retained online status)";
  row("broker link", link);
  for (const h of view.health) row(h.label, fmtNumber(h.value, h.unit));
  const age = el("td", { class: "age" }, "-");
  table.append(el("tr", {}, el("th", {}, "last snapshot"), age));
  card.ageEl = age;
  updateAge(card);
  const extra = card.root.querySelector("table.extra");
  extra.replaceChildren();
  for (const [k, v] of Object.entries(view.extra || {})) {
    extra.append(el("tr", {}, el("th", {}, k), el("td", {}, fmtNumber(v, ""))));
  }
}

function renderReadouts(card) {
  const r = card.view.readouts || {};
  const table = card.root.querySelector("table.readouts");
  table.replaceChildren();
  const chans = Object.keys(r.channels || {});
  if (!chans.length) {
    if (r.note) table.append(el("tr", {}, el("td", {}, r.note)));
    return;
  }
  table.append(el("tr", {}, el("th", {}, `readouts (${r.note})`),
                  el("th", {}, "N (white)"), el("th", {}, "B (bias instability)"),
                  el("th", {}, "K (random walk)")));
  for (const ch of chans) {
    const tr = el("tr", { "data-channel": ch }, el("th", {}, ch));
    for (const term of ["N", "B", "K"]) {
      const x = r.channels[ch].find((e) => e.term === term);
      tr.append(el("td", { class: x ? x.kind : "none", title: x ? x.note : "" },
                   x ? x.text : "-"));
    }
    table.append(tr);
  }
}

function renderJig(card) {
  const jig = card.view.jig;
  const box = card.root.querySelector(".jig");
  box.replaceChildren();
  if (!jig) return;
  const verdict = String(jig.verdict ?? "-");
  box.append(el("h3", {}, "jig: ", el("span", { class: `verdict-${verdict.toLowerCase()}` },
                                       verdict)));
  const cols = ["name", "value", "unit", "low", "high", "ci_low", "ci_high", "verdict"];
  if (Array.isArray(jig.measurements) && jig.measurements.length) {
    const table = el("table", { class: "jig-measurements" },
                     el("tr", {}, ...cols.map((c) => el("th", {}, c))));
    for (const m of jig.measurements) {
      table.append(el("tr", {}, ...cols.map((c) => el("td",
        c === "verdict" ? { class: `verdict-${String(m[c]).toLowerCase()}` } : {},
        fmtNumber(m[c] ?? null, "")))));
    }
    box.append(table);
  }
  const other = Object.entries(jig).filter(([k]) => k !== "verdict" && k !== "measurements");
  if (other.length) {
    const table = el("table", {});
    for (const [k, v] of other) table.append(el("tr", {}, el("th", {}, k),
                                                el("td", {}, fmtNumber(v, ""))));
    box.append(table);
  }
}

function render(card) {
  const view = card.view;
  const stats = Object.keys(view.statistics || {});
  if (!card.stat || !stats.includes(card.stat)) card.stat = view.statistic || stats[0] || null;
  card.select.replaceChildren(...stats.map((s) => el("option", { value: s }, s)));
  card.select.hidden = stats.length < 2;
  if (card.stat) card.select.value = card.stat;
  card.root.dataset.state = view.state;
  card.stateEl.className = `state ${view.state}`;
  card.stateEl.textContent = view.state;
  const chip = view.health.find((h) => h.key === "chip");
  const odr = view.health.find((h) => h.key === "odr_hz");
  const samples = view.health.find((h) => h.key === "samples");
  card.root.dataset.samples = samples ? String(samples.value) : "0";
  card.metaEl.textContent = [chip && chip.value, odr && fmtNumber(odr.value, "Hz"),
                             view.memory && `memory ${view.memory}`].filter(Boolean).join(" · ");
  if (card.stat) renderPlots(card);
  renderHealth(card);
  renderReadouts(card);
  renderJig(card);
  card.root.querySelector(".errors").textContent = (view.errors || []).join("; ");
}

function updateAge(card) {
  if (!card.ageEl) return;
  const a = card.view.age_s;
  card.ageEl.textContent = a === null ? "none yet"
    : `${(a + (performance.now() - card.receivedAt) / 1000).toFixed(0)} s ago`;
}

function updateSummary() {
  const counts = {};
  for (const c of cards.values()) counts[c.view.state] = (counts[c.view.state] || 0) + 1;
  document.getElementById("summary").textContent = `${cards.size} sensor(s): ` +
    Object.entries(counts).map(([s, n]) => `${n} ${s}`).join(", ");
}

const source = new EventSource("events");
let opened = false;
source.addEventListener("open", () => {
  const link = document.getElementById("link");
  link.dataset.live = "true"; link.textContent = "live";
  // a new stream sends the whole fleet again, and no "remove" for sensors that went
  // while it was down (a restarted view server): drop the old cards first
  if (opened) {
    for (const c of cards.values()) c.root.remove();
    cards.clear();
    updateSummary();
  }
  opened = true;
});
source.addEventListener("error", () => {
  const link = document.getElementById("link");
  link.dataset.live = "false"; link.textContent = "view server unreachable, retrying";
});
source.addEventListener("broker", (e) => {
  const b = JSON.parse(e.data);
  const node = document.getElementById("broker");
  node.dataset.connected = String(b.connected);
  node.textContent = `broker ${b.url}: ` + (b.connected ? "connected"
    : `disconnected${b.last_error ? " (" + b.last_error + ")" : ""}`);
});
source.addEventListener("sensor", (e) => {
  const view = JSON.parse(e.data);
  const card = cards.get(view.key) || makeCard(view);
  card.view = view;
  card.receivedAt = performance.now();
  render(card);
  updateSummary();
});
source.addEventListener("remove", (e) => {
  const { key } = JSON.parse(e.data);
  const card = cards.get(key);
  if (!card) return;
  card.root.remove();
  cards.delete(key);
  document.getElementById("empty").hidden = cards.size > 0;
  updateSummary();
});
setInterval(() => { for (const c of cards.values()) updateAge(c); }, 1000);
window.addEventListener("resize", () => {
  for (const c of cards.values()) {
    for (const [group, u] of Object.entries(c.plots)) {
      const holder = c.root.querySelector(`.plot[data-group="${group}"]`);
      if (u && holder.clientWidth) u.setSize({ width: holder.clientWidth, height: 260 });
    }
  }
});
