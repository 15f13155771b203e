// telethermal view: live frames over Server-Sent Events, recordings over
// fetch, drawn on canvases. Every series is a rolling window (WINDOW_S of
// data), so a session of any length holds a bounded number of points.
"use strict";
const WINDOW_S = 20;
const COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
                "#7f7f7f", "#bcbd22", "#17becf"];
const $ = (id) => document.getElementById(id);

class Plot {
  // series: [name, label, color, dash, sign]; a series of sign -1 is drawn
  // negated (a flux into the finger, drawn out of it: the one convention).
  constructor(id, series) {
    this.canvas = $(id);
    this.ctx = this.canvas.getContext("2d");
    this.series = series.map(([name, label, color, dash, sign = 1]) =>
      ({name, label, color, dash, sign, pts: []}));
    this.marker = null;          // [x, text]
  }
  get(name) { return this.series.find((s) => s.name === name); }
  clear() { for (const s of this.series) s.pts = []; this.marker = null; }
  push(name, pts) {
    const s = this.get(name);
    for (const p of pts) s.pts.push(s.sign === 1 ? p : [p[0], s.sign * p[1]]);
  }
  trim(tMin) {
    for (const s of this.series) {
      let i = 0;
      while (i < s.pts.length && s.pts[i][0] < tMin) i++;
      if (i) s.pts.splice(0, i);
    }
  }
  points() { return this.series.reduce((n, s) => n + s.pts.length, 0); }
  draw(x0, x1, upTo = Infinity) {
    const {ctx, canvas} = this, W = canvas.width, H = canvas.height, L = 58, R = 8, T = 18, B = 20;
    ctx.clearRect(0, 0, W, H);
    let lo = Infinity, hi = -Infinity;
    const spans = this.series.map((s) => {
      const a = lowerBound(s.pts, x0), b = lowerBound(s.pts, Math.min(x1, upTo) + 1e-9);
      for (let i = a; i < b; i++) { const v = s.pts[i][1]; if (v < lo) lo = v; if (v > hi) hi = v; }
      return [a, b];
    });
    this.canvas.dataset.points = String(this.points());
    if (!(hi >= lo)) { lo = 0; hi = 1; }
    if (hi - lo < 1e-9) { lo -= 0.5; hi += 0.5; }
    const pad = 0.05 * (hi - lo); lo -= pad; hi += pad;
    const sx = (x) => L + (x - x0) / Math.max(x1 - x0, 1e-9) * (W - L - R);
    const sy = (y) => T + (hi - y) / (hi - lo) * (H - T - B);
    ctx.strokeStyle = "#ccc"; ctx.fillStyle = "#555"; ctx.font = "11px sans-serif"; ctx.lineWidth = 1;
    ctx.strokeRect(L, T, W - L - R, H - T - B);
    for (const y of ticks(lo, hi, 4)) {
      ctx.fillText(fmt(y), 2, sy(y) + 4);
      ctx.beginPath(); ctx.moveTo(L, sy(y)); ctx.lineTo(W - R, sy(y)); ctx.stroke();
    }
    for (const x of ticks(x0, x1, 8)) ctx.fillText(fmt(x), sx(x) - 8, H - 5);
    let legendX = L + 6;
    this.series.forEach((s, k) => {
      const [a, b] = spans[k];
      ctx.strokeStyle = s.color; ctx.lineWidth = 1.4; ctx.setLineDash(s.dash ? [5, 3] : []);
      ctx.beginPath();
      for (let i = a; i < b; i++) {
        const p = s.pts[i];
        if (i === a) ctx.moveTo(sx(p[0]), sy(p[1])); else ctx.lineTo(sx(p[0]), sy(p[1]));
      }
      ctx.stroke(); ctx.setLineDash([]);
      ctx.fillStyle = s.color; ctx.fillText(s.label, legendX, 12);
      legendX += ctx.measureText(s.label).width + 14;
    });
    if (this.marker) {
      const [x, text] = this.marker;
      ctx.strokeStyle = "#000"; ctx.setLineDash([2, 2]);
      ctx.beginPath(); ctx.moveTo(sx(x), T); ctx.lineTo(sx(x), H - B); ctx.stroke(); ctx.setLineDash([]);
      ctx.fillStyle = "#000"; ctx.fillText(text, Math.min(sx(x) + 4, W - 120), T + 12);
    }
  }
}

function lowerBound(pts, x) {
  let a = 0, b = pts.length;
  while (a < b) { const m = (a + b) >> 1; if (pts[m][0] < x) a = m + 1; else b = m; }
  return a;
}
function ticks(lo, hi, n) {
  const step = Math.pow(10, Math.floor(Math.log10((hi - lo) / n)));
  const k = [1, 2, 5, 10].find((f) => (hi - lo) / (f * step) <= n) * step;
  const out = [];
  for (let v = Math.ceil(lo / k) * k; v <= hi; v += k) out.push(v);
  return out;
}
function fmt(v) { return Math.abs(v) >= 1000 ? v.toFixed(0) : Number(v.toPrecision(3)).toString(); }

const plots = {
  temp: new Plot("plot-temp", [["master_temp", "master pad", COLORS[0]],
                               ["slave_temp", "slave pad", COLORS[1]],
                               ["skin", "skin (estimate)", COLORS[2], true]]),
  // The master's flux and the slave's setpoint are the display's flux into
  // the finger: drawn out of it (positive into the display, as the slave
  // pad's is into its object), as every plot of the project draws flux.
  masterFlux: new Plot("plot-master-flux", [["master_setpoint", "setpoint", "#000", true, -1],
                                            ["master_flux", "measured", COLORS[0], false, -1]]),
  slaveFlux: new Plot("plot-slave-flux", [["slave_setpoint", "setpoint (naive)", "#000", true, -1],
                                          ["slave_flux", "measured", COLORS[1]]]),
};
const SERIES_PLOT = {master_temp: "temp", slave_temp: "temp", skin: "temp",
                     master_setpoint: "masterFlux", master_flux: "masterFlux",
                     slave_setpoint: "slaveFlux", slave_flux: "slaveFlux"};
let posterior = {plot: null, classes: [], contact: null};

function posteriorPlot(classes) {
  if (posterior.plot && posterior.classes.join() === classes.join()) return posterior.plot;
  posterior = {plot: new Plot("plot-posterior", classes.map((c, i) => [c, c, COLORS[i % 10]])),
               classes, contact: null};
  return posterior.plot;
}
function addEstimate(e, contactId) {
  const plot = posteriorPlot(e.classes);
  // (contact 0: no touch going on; the last contact's history stays shown)
  if (contactId && posterior.contact !== contactId) { plot.clear(); posterior.contact = contactId; }
  const last = plot.series[0].pts;
  if (last.length && last[last.length - 1][0] >= e.t_s) return;
  e.classes.forEach((c, i) => plot.push(c, [[e.t_s, e.posteriors[i]]]));
  showDecision(e, plot);
}
// A new material (outside every trained class) with its effusivity estimate
// and 95 % interval, W s^0.5/(m^2 K), and the nearest class (ident/openset.py).
function newMaterial(e) {
  if (e.label !== "new material" || e.effusivity_w_s05_m2k == null) return "";
  const f = (v) => Number(v.toPrecision(3)).toLocaleString("en-US");
  const near = e.nearest ? `, nearest: ${e.nearest}` : "";
  return `, effusivity ${f(e.effusivity_w_s05_m2k)} W s^0.5/(m^2 K) (95 %: ` +
    `${f(e.effusivity_lo_w_s05_m2k)} to ${f(e.effusivity_hi_w_s05_m2k)})${near}`;
}
function showDecision(e, plot) {
  const el = $("decision");
  if (e.decided) {
    // An "unknown" says why (README, the table of reasons).
    const why = e.label === "unknown" && e.reason ? ` (${e.reason})` : "";
    el.textContent = `${e.label}${why}${newMaterial(e)} at ${e.t_s.toFixed(2)} s`;
    el.dataset.label = e.label;
    plot.marker = [e.t_s, `decided: ${e.label}`];
  } else {
    el.textContent = `${e.label}? (undecided, ${e.t_s.toFixed(2)} s)`;
    el.dataset.label = "";
    plot.marker = null;
  }
}
function drawPosterior() {
  if (!posterior.plot) return;
  const pts = posterior.plot.series[0].pts;
  const x1 = pts.length ? Math.max(pts[pts.length - 1][0] * 1.1, 0.2) : 1;
  posterior.plot.draw(0, x1);
}
function showState(s) {
  if (!s) return;
  $("phase").textContent = s.phase;
  $("safe").textContent = s.safe ? "SAFE STATE" : "no";
  const ev = Object.entries(s.events || {}).filter(([, n]) => n);
  $("events").textContent = ev.length ? ev.map(([k, n]) => `${k}: ${n}`).join(", ") : "none";
  $("rtt").textContent = s.rtt_s == null ? "–" : `${(s.rtt_s * 1000).toFixed(2)} ms`;
  for (const [k, v] of Object.entries(s.link || {})) {
    let cell = $(`link-${k}`);
    if (!cell) {
      const row = $("link").insertRow(); row.insertCell().outerHTML = `<th>${k.replace(/_/g, " ")}</th>`;
      cell = row.insertCell(); cell.id = `link-${k}`;
    }
    cell.textContent = v;
  }
}
function message(text, note = false) {
  const el = $("message");
  el.hidden = !text; el.textContent = text || ""; el.className = note ? "message note" : "message";
}

// ------------------------------------------------------------------ live
const live = {t: 0, counts: {master: 0, slave: 0, slave_setpoint: 0}, frames: 0, lags: [],
              newFrames: [], source: null, dirty: false};
function onFrame(ev) {
  const f = JSON.parse(ev.data);
  live.frames++; live.t = f.t_s;
  for (const [name, pts] of Object.entries(f.series)) plots[SERIES_PLOT[name]].push(name, pts);
  for (const [k, n] of Object.entries(f.counts)) live.counts[k] += n;
  if (f.state) {
    showState(f.state);
    if (f.state.estimate) addEstimate(f.state.estimate, f.state.contact_id);
  }
  if (f.data_s != null) live.newFrames.push(f);
  live.dirty = true;
}
function drawLive() {
  const now = Date.now() / 1000;
  for (const f of live.newFrames) live.lags.push((f.mono_s - f.data_s) + (now - f.wall_s));
  live.newFrames = [];
  if (live.lags.length > 4000) live.lags.splice(0, live.lags.length - 4000);
  const x0 = Math.max(0, live.t - WINDOW_S), x1 = x0 + WINDOW_S;
  for (const p of Object.values(plots)) { p.trim(x0); p.draw(x0, x1); }
  drawPosterior();
  for (const [k, n] of Object.entries(live.counts)) { $(`count-${k}`).textContent = n; $(`count-${k}`).dataset.value = n; }
  $("frames").textContent = live.frames; $("frames").dataset.value = live.frames;
}
function lagP99() {
  if (!live.lags.length) return;
  const s = [...live.lags].sort((a, b) => a - b), p = s[Math.min(s.length - 1, Math.floor(0.99 * s.length))];
  $("lag-p99").textContent = `${(p * 1000).toFixed(0)} ms`; $("lag-p99").dataset.value = String(p);
}
function startLive() {
  stopPlayback();
  for (const p of Object.values(plots)) p.clear();
  $("mode").textContent = "live"; $("mode").dataset.mode = "live";
  live.source = new EventSource("/api/events");
  live.source.onmessage = onFrame;
  live.source.onerror = () => message("live stream interrupted; reconnecting…", true);
  live.source.onopen = () => message("");
}
function stopLive() {
  if (live.source) { live.source.close(); live.source = null; }
  live.lags = []; live.newFrames = []; live.counts = {master: 0, slave: 0, slave_setpoint: 0};
}

// ------------------------------------------------------------------ playback
const play = {rec: null, cursor: 0, playing: false, last: null};
async function loadRecording(name) {
  stopLive();
  stopPlayback();
  $("mode").textContent = `recording ${name}`; $("mode").dataset.mode = "recording";
  $("playback-status").textContent = "loading…"; $("playback-status").dataset.state = "loading";
  const resp = await fetch(`/api/recording?name=${encodeURIComponent(name)}`);
  const body = await resp.json();
  if (!resp.ok) {
    message(body.error); $("playback-status").textContent = "cannot play";
    $("playback-status").dataset.state = "error"; return;
  }
  const notes = (body.notes || []).slice();
  if (body.truncated) notes.unshift(`this recording was cut mid-write (${body.truncated}): it plays up to the cut`);
  message(notes.join("; "), true);
  play.rec = body; play.cursor = body.t_min;
  // What only a live session has: cleared, not left over from it.
  for (const cell of document.querySelectorAll("[id^=link-]")) cell.textContent = "–";
  $("rtt").textContent = "–"; $("lag-p99").textContent = "–"; $("lag-p99").dataset.value = "";
  $("count-slave_setpoint").textContent = "0"; $("count-slave_setpoint").dataset.value = "0";
  $("decision").textContent = "–"; $("decision").dataset.label = "";
  for (const p of Object.values(plots)) p.clear();
  for (const [name, pts] of Object.entries(body.series)) if (SERIES_PLOT[name]) plots[SERIES_PLOT[name]].push(name, pts);
  $("count-master").textContent = body.counts.master; $("count-master").dataset.value = body.counts.master;
  $("count-slave").textContent = body.counts.slave; $("count-slave").dataset.value = body.counts.slave;
  const sl = $("slider"); sl.min = body.t_min; sl.max = body.t_max; sl.value = body.t_min; sl.disabled = false;
  $("play").disabled = false;
  $("playback-status").textContent = "ready"; $("playback-status").dataset.state = "ready";
  drawPlayback();
}
function drawPlayback() {
  const r = play.rec; if (!r) return;
  const c = play.cursor, x1 = Math.max(c, r.t_min + Math.min(WINDOW_S, r.t_max - r.t_min)), x0 = Math.max(r.t_min, x1 - WINDOW_S);
  for (const p of Object.values(plots)) p.draw(x0, x1, c);
  $("cursor").textContent = `${(c - r.t_min).toFixed(2)} / ${(r.t_max - r.t_min).toFixed(2)} s`;
  $("slider").value = c;
  const ph = r.series.phase.filter((p) => p[0] <= c).pop();
  const end = r.touch_ends.filter((e) => e[0] <= c).pop();     // the last touch's summary
  if (ph) showState({phase: ph[1], safe: ph[2], events: end ? end[1] : {},
                     link: end ? end[2] : {}, rtt_s: end ? end[3] : null});
  const est = r.estimates.filter((e) => e.t <= c);
  if (est.length) {
    const cid = est[est.length - 1].contact_id;
    const plot = posteriorPlot(est[est.length - 1].classes); plot.clear(); posterior.contact = cid;
    for (const e of est.filter((x) => x.contact_id === cid)) addEstimate(e, cid);
    drawPosterior();
  }
}
function tick(ts) {
  if (play.playing && play.rec) {
    const dt = play.last == null ? 0 : (ts - play.last) / 1000;
    play.cursor = Math.min(play.rec.t_max, play.cursor + dt * Number($("speed").value));
    if (play.cursor >= play.rec.t_max) {
      play.playing = false; $("play").textContent = "play";
      $("playback-status").textContent = "end of recording"; $("playback-status").dataset.state = "ended";
    }
    drawPlayback();
  }
  play.last = ts;
  if (live.source && live.dirty) { live.dirty = false; drawLive(); }
  requestAnimationFrame(tick);
}
function stopPlayback() { play.playing = false; play.rec = null; $("play").disabled = true; $("slider").disabled = true; }

$("play").onclick = () => {
  if (!play.rec) return;
  if (play.cursor >= play.rec.t_max) play.cursor = play.rec.t_min;
  play.playing = !play.playing;
  $("play").textContent = play.playing ? "pause" : "play";
  $("playback-status").textContent = play.playing ? "playing" : "paused";
  $("playback-status").dataset.state = play.playing ? "playing" : "paused";
};
$("slider").oninput = () => { play.cursor = Number($("slider").value); drawPlayback(); };
$("recording").onchange = () => { const n = $("recording").value; if (n) loadRecording(n); else if (window.viewInfo.live) startLive(); };

async function init() {
  const info = window.viewInfo = await (await fetch("/api/info")).json();
  for (const name of info.recordings) {
    const o = document.createElement("option"); o.value = o.textContent = name; $("recording").appendChild(o);
  }
  if (info.live) startLive(); else { $("mode").textContent = "no live session (recordings only)"; $("mode").dataset.mode = "idle"; }
  if (info.message) message(info.message, true);
  requestAnimationFrame(tick);
  setInterval(lagP99, 1000);
}
window.viewStats = {fcp_ms: null};
new PerformanceObserver((list) => {
  for (const e of list.getEntries()) if (e.name === "first-contentful-paint") window.viewStats.fcp_ms = e.startTime;
}).observe({type: "paint", buffered: true});
for (const p of Object.values(plots)) p.draw(0, WINDOW_S);
init();
