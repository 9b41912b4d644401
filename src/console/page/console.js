// The mfd console page. Everything it needs comes from the mfd process
// that serves it. Its state is in window.mfdConsole (the browser test reads it).
// Data (names, paths, messages) reaches the DOM only as text (textContent,
// attributes set as properties), never as markup: a result file may be
// named "<img src=x onerror=...>.png".
"use strict";
const S = (window.mfdConsole = {
  status: null, statusMessages: 0, previews: 0, lastPreview: null,
  previewNonBlank: 0, results: [], resultsVersion: -1, errors: [], policyViolations: [],
});
// A policy violation means something of the page's own is blocked: keep it
// where the browser test reads it.
document.addEventListener("securitypolicyviolation", (e) => {
  S.policyViolations.push(`${e.violatedDirective}: ${e.blockedURI}`);
});
// Off loopback every request carries the token of the page's address.
const token = new URLSearchParams(location.search).get("token");
// The token of this process, which changes need in X-Mfd-Token: another
// site's page can neither read it nor send that header.
const pageToken = document.querySelector('meta[name="mfd-token"]').content;
function api(path) {
  if (!token) return path;
  return path + (path.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token);
}
const $ = (id) => document.getElementById(id);
// An element with its class and text (text only: never parsed as markup).
function el(tag, className, text) {
  const e = document.createElement(tag);
  if (className) e.className = className;
  if (text !== undefined) e.textContent = String(text);
  return e;
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const fmt = (x, d) => (x === null || x === undefined ? "–" : Number(x).toFixed(d));

function connect() {
  const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + api("/api/ws");
  const ws = new WebSocket(url);
  ws.onmessage = (ev) => { S.statusMessages++; showStatus(JSON.parse(ev.data)); };
  ws.onclose = () => setTimeout(connect, 1000);
}

function showStatus(st) {
  S.status = st;
  document.body.classList.toggle("results-only", st.mode === "results");
  $("mode").textContent = st.mode;
  const stage = $("stage");
  stage.textContent = st.stage.state + (st.stage.error ? ": " + st.stage.error : "") +
    (st.stop_requested && st.stage.state === "acquiring" ? " (stopping…)" : "");
  stage.className = "stage " + st.stage.state;
  $("stop").disabled = !st.can_stop || st.stop_requested ||
    ["done", "stopped", "failed"].includes(st.stage.state);
  if (st.showing) drawPattern(st.showing, st.screen_px);
  const p = st.progress;
  if (p) {
    $("bar-fill").style.width = (100 * p.done / Math.max(1, p.total)).toFixed(1) + "%";
    const rows = [
      ["frames", `${p.done} of ${p.total}` + (p.first ? ` (this run from ${p.first})` : "")],
      ["frames/s", fmt(p.frames_per_s, 1)],
      ["time left", p.time_left_s === null ? "–" : fmt(p.time_left_s, 0) + " s"],
      ["elapsed", fmt(p.elapsed_s, 1) + " s"],
      ["waits on consumers", `${p.waits} (${fmt(p.wait_s, 2)} s)`],
      ["re-shoots", p.reshoots],
      ["drops", `${p.drops} (timeouts ${p.timeouts}, incomplete ${p.incomplete})`],
      ["mismatched frames", p.mismatches],
      ["lost frames", p.lost_frames],
    ];
    $("progress").tBodies[0].replaceChildren(...rows.map(([k, v]) => {
      const tr = el("tr");
      tr.append(el("td", null, k), el("td", null, v));
      return tr;
    }));
  }
  const sp = st.spectral;
  $("spectral").textContent = {
    off: () => "not run",
    streaming: () => `streaming: ${sp.frames_in} of ${sp.frames_total} frames in`,
    fitting: () => `fitting: ${sp.pixels_done} of ${sp.pixels_total} pixels`,
    done: () => `done: both reflections found in ${sp.both_found} of ${sp.pixels} pixels`,
  }[sp.state]();
  if (st.results_version !== S.resultsVersion) {
    S.resultsVersion = st.results_version;
    loadResults();
  }
}

// The pattern as the screen shows it: g = 0.5 + 0.5 cos(2π τ s + φ), with
// the fringe coordinate s of the interchange spec over the whole screen.
function drawPattern(sh, screen) {
  const c = $("pattern"), ctx = c.getContext("2d");
  const [W, H] = screen || [16, 9];
  c.height = Math.round(c.width * H / W);
  const img = ctx.createImageData(c.width, c.height);
  const t = sh.direction_deg * Math.PI / 180, co = Math.cos(t), si = Math.sin(t);
  const proj = [0, W * co, H * si, W * co + H * si];
  const s0 = Math.min(...proj), L = Math.max(...proj) - s0;
  for (let y = 0; y < c.height; y++) for (let x = 0; x < c.width; x++) {
    const u = (x + 0.5) * W / c.width, v = (y + 0.5) * H / c.height;
    const s = (u * co + v * si - s0) / L;
    const g = 255 * (0.5 + 0.5 * Math.cos(2 * Math.PI * sh.tau * s + sh.phase_rad));
    const k = 4 * (y * c.width + x);
    img.data[k] = img.data[k + 1] = img.data[k + 2] = g; img.data[k + 3] = 255;
  }
  ctx.putImageData(img, 0, 0);
  $("pattern-label").textContent =
    `#${sh.index}: direction ${fmt(sh.direction_deg, 0)}°, τ ${fmt(sh.tau, 2)}, phase ${fmt(sh.phase_rad, 3)} rad`;
}

// The preview, throttled by this page: ask for the next frame once this one is drawn.
async function previewLoop() {
  let after = null;
  for (;;) {
    try {
      const q = "/api/preview?wait_ms=10000" + (after === null ? "" : "&after=" + after);
      const r = await fetch(api(q), { cache: "no-store" });
      if (r.status === 200) {
        const p = await r.json();
        await drawPreview(p);
        after = p.index;
      } else if (r.status !== 204) {
        await sleep(1000);
      }
    } catch (e) {
      S.errors.push(String(e));
      await sleep(1000);
    }
  }
}

async function drawPreview(p) {
  // Decoded from bytes, not loaded from a data: address, which the policy
  // (default-src 'self') does not allow.
  const bytes = Uint8Array.from(atob(p.png_base64), (ch) => ch.charCodeAt(0));
  const img = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
  const c = $("preview"), ctx = c.getContext("2d");
  c.width = p.width; c.height = p.height;
  ctx.drawImage(img, 0, 0);
  img.close();
  const px = ctx.getImageData(0, 0, c.width, c.height).data;
  let lit = 0;
  for (let k = 0; k < px.length; k += 4) if (px[k] || px[k + 1] || px[k + 2]) lit++;
  S.previewNonBlank = lit;
  drawHistogram(p);
  $("frame-label").textContent = `frame ${p.index}`;
  $("saturated").textContent = p.saturated;
  $("range").textContent = `${p.min}–${p.max}, mean ${fmt(p.mean, 1)}`;
  $("full-scale").textContent = p.full_scale;
  S.lastPreview = { index: p.index, width: p.width, height: p.height, saturated: p.saturated, max: p.max };
  S.previews++;
}

function drawHistogram(p) {
  const c = $("histogram"), ctx = c.getContext("2d");
  ctx.clearRect(0, 0, c.width, c.height);
  const n = p.histogram.length, w = c.width / n;
  const top = Math.log1p(Math.max(...p.histogram));
  for (let k = 0; k < n; k++) {
    const h = top > 0 ? (c.height - 14) * Math.log1p(p.histogram[k]) / top : 0;
    ctx.fillStyle = k === n - 1 && p.saturated > 0 ? "#e00" : "#1565c0";
    ctx.fillRect(k * w, c.height - 12 - h, w - 1, h);
  }
  ctx.fillStyle = "#555"; ctx.font = "10px 'DejaVu Sans'";
  ctx.fillText("0", 0, c.height - 1);
  ctx.fillText(String(p.full_scale), c.width - 30, c.height - 1);
  ctx.fillText("counts (log scale of pixels)", c.width / 2 - 70, c.height - 1);
}

// A link to a result file (its address comes percent-encoded from mfd; one
// that is not under /results/ is not shown).
function fileLink(f, child) {
  const a = el("a");
  if (typeof f.url === "string" && f.url.startsWith("/results/")) a.href = api(f.url);
  if (f.kind === "download") a.download = f.name;
  a.append(child);
  return a;
}

function resultDir(dir) {
  const div = el("div", "result");
  div.append(el("h3", null, dir.name), el("p", "note", dir.path));
  if (!dir.files.length) div.append(el("p", "note", "no files yet"));
  for (const f of dir.files.filter((f) => f.kind === "picture")) {
    const fig = el("figure");
    const img = el("img");
    img.alt = f.name;
    if (f.url.startsWith("/results/")) img.src = api(f.url);
    fig.append(fileLink(f, img), el("figcaption", null, f.name));
    div.append(fig);
  }
  const other = dir.files.filter((f) => f.kind !== "picture");
  if (other.length) {
    const p = el("p");
    other.forEach((f, k) => {
      if (k) p.append(" · ");
      p.append(fileLink(f, f.name + (f.kind === "download" ? " ⤓" : "")));
    });
    div.append(p);
  }
  return div;
}

async function loadResults() {
  try {
    const r = await fetch(api("/api/results"), { cache: "no-store" });
    const list = await r.json();
    S.results = list;
    const divs = [];
    for (const dir of list) {
      const div = resultDir(dir);
      const summary = dir.files.find((f) => f.name === "summary.json");
      if (summary) {
        const text = JSON.stringify(await (await fetch(api(summary.url))).json(), null, 1);
        div.append(el("pre", null, text));
      }
      divs.push(div);
    }
    if (!divs.length) divs.push(el("p", "note", "none yet"));
    $("results").replaceChildren(...divs);
  } catch (e) {
    S.errors.push(String(e));
  }
}

$("stop").onclick = async () => {
  $("stop").disabled = true;
  await fetch(api("/api/stop"), { method: "POST", headers: { "X-Mfd-Token": pageToken } });
};

connect();
previewLoop();
