// The backplot: the planned and the executed path on a grid in the work system, and the
// work offset table beside it.
function sizeCanvas(c) {
  const ratio = window.devicePixelRatio || 1;
  const w = c.clientWidth, h = c.clientHeight;
  if (c.width !== Math.round(w * ratio) || c.height !== Math.round(h * ratio)) {
    c.width = Math.round(w * ratio); c.height = Math.round(h * ratio);
  }
  const g = c.getContext("2d");
  g.setTransform(ratio, 0, 0, ratio, 0, 0);
  g.clearRect(0, 0, w, h);
  return [g, w, h];
}

// The executed path of the job (or the last one), from the daemon's recording: everything
// cut so far, also when the page was opened mid-job.
async function loadExecuted() {
  if (executedBusy) return;
  executedBusy = true; executedAt = Date.now();
  try {
    const r = await fetch("/api/executed");
    executedPath = r.ok ? await r.json() : null;
  } catch (e) { /* the plot keeps what it had */ }
  executedBusy = false;
  showEvents(); draw();
}

// A grid step of 1, 2 or 5 × 10^k mm giving about `lines` lines over `span` mm.
function gridStep(span, lines) {
  const raw = span / lines, p = Math.pow(10, Math.floor(Math.log10(raw)));
  return [1, 2, 5, 10].map((k) => k * p).find((s) => s >= raw * 0.999);
}

// The backplot, in the active work system's coordinates (mm): a grid with its values, the
// work zero's axes, a scale bar, the soft limits as a dashed box; the programmed path (grey,
// rapids dashed), the cut (blue), turn-backs (violet), shorts (red crosses), the electrode.
function draw() {
  const c = $("backplot");
  const [g, w, h] = sizeCanvas(c);
  const css = (v) => getComputedStyle(document.body).getPropertyValue(v);
  const toWork = ([x, y]) => [x - workOffset[0], y - workOffset[1]];
  const running = $("state").dataset.state !== "idle";
  const mine = executedPath && (running || !plannedFor || executedPath.program === plannedFor ||
    executedPath.program.endsWith(`/${plannedFor}`));
  const exec = mine ? executedPath : { path: [], turn_backs: [], rapids: [], shorts: [] };
  // The executed path in the work system its program is in (a G55 program's cut lies on
  // its G55 drawing whatever the machine's system is now).
  const off = exec.work_offset_mm || workOffset;
  const toJob = ([x, y]) => [x - off[0], y - off[1]];
  const path = exec.path.map(toJob), turns = exec.turn_backs.map((s) => s.map(toJob));
  const rapids = exec.rapids.map((s) => s.map(toJob)), shorts = exec.shorts.map(toJob);
  const box = travel[0] && travel[1]
    ? [travel[0][0] - workOffset[0], travel[1][0] - workOffset[1], travel[0][1] - workOffset[0], travel[1][1] - workOffset[1]]
    : null;
  const pts = [];
  if (planned) planned.strokes.forEach((s) => s.points.forEach((p) => pts.push(p)));
  path.forEach((p) => pts.push(p));
  if (here) pts.push(toWork(here));
  if (pts.length < 2 && box) pts.push([box[0], box[1]], [box[2], box[3]]);
  let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
  pts.forEach(([x, y]) => { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); });
  if (!pts.length) [x0, y0, x1, y1] = [-1, -1, 1, 1];
  const span = Math.max(x1 - x0, y1 - y0, 0.01);
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  const pad = { l: 46, r: 12, t: 12, b: 24 };
  const k = Math.min((w - pad.l - pad.r) / (span * 1.1), (h - pad.t - pad.b) / (span * 1.1));
  const X = (x) => pad.l + (w - pad.l - pad.r) / 2 + (x - cx) * k;
  const Y = (y) => pad.t + (h - pad.t - pad.b) / 2 - (y - cy) * k;
  const left = cx - (w - pad.l - pad.r) / 2 / k, right = cx + (w - pad.l - pad.r) / 2 / k;
  const bottom = cy - (h - pad.t - pad.b) / 2 / k, top = cy + (h - pad.t - pad.b) / 2 / k;
  const step = gridStep(Math.max(right - left, top - bottom), 8);
  const digits = Math.max(0, -Math.floor(Math.log10(step)));
  g.lineWidth = 1; g.font = "11px system-ui, sans-serif"; g.fillStyle = css("--dim");
  for (let x = Math.ceil(left / step) * step; x <= right; x += step) {
    g.strokeStyle = Math.abs(x) < step / 2 ? "#8c959f" : "#e6e9ec";
    g.beginPath(); g.moveTo(X(x), pad.t); g.lineTo(X(x), h - pad.b); g.stroke();
    g.textAlign = "center"; g.fillText(x.toFixed(digits), X(x), h - 8);
  }
  for (let y = Math.ceil(bottom / step) * step; y <= top; y += step) {
    g.strokeStyle = Math.abs(y) < step / 2 ? "#8c959f" : "#e6e9ec";
    g.beginPath(); g.moveTo(pad.l, Y(y)); g.lineTo(w - pad.r, Y(y)); g.stroke();
    g.textAlign = "right"; g.fillText(y.toFixed(digits), pad.l - 4, Y(y) + 4);
  }
  g.textAlign = "left"; g.fillStyle = css("--ink");
  g.fillText(`${axes[0] || "X"} →`, w - pad.r - 26, h - pad.b - 4);
  g.fillText(`${axes[1] || "Y"} ↑`, pad.l + 4, pad.t + 10);
  // The scale bar: one grid step.
  g.strokeStyle = css("--ink"); g.lineWidth = 2; g.beginPath();
  g.moveTo(w - pad.r - 8 - step * k, pad.t + 8); g.lineTo(w - pad.r - 8, pad.t + 8); g.stroke();
  g.textAlign = "right"; g.fillText(`${step.toFixed(digits)} mm (work)`, w - pad.r - 8, pad.t + 22);
  if (box) {
    g.setLineDash([6, 4]); g.strokeStyle = "#8c959f"; g.lineWidth = 1.5;
    g.strokeRect(X(box[0]), Y(box[3]), (box[2] - box[0]) * k, (box[3] - box[1]) * k);
  }
  const stroke = (points, color, width, dash) => {
    if (points.length < 2) return;
    g.beginPath(); g.setLineDash(dash); g.strokeStyle = color; g.lineWidth = width;
    points.forEach(([x, y], i) => (i ? g.lineTo(X(x), Y(y)) : g.moveTo(X(x), Y(y))));
    g.stroke();
  };
  let plannedCount = 0, turnBack = 0;
  if (planned) planned.strokes.forEach((s) => { stroke(s.points, "#adb5bd", 1, s.rapid ? [4, 4] : []); plannedCount += s.points.length; });
  rapids.forEach((s) => stroke(s, "#79a8f0", 1.5, [4, 3]));
  // A dry run moved the path and cut nothing: drawn as travel, never as a cut.
  stroke(path, exec.dry_run ? "#79a8f0" : css("--accent"), 2, exec.dry_run ? [2, 3] : []);
  turns.forEach((s) => { stroke(s, css("--turn"), 2.5, []); turnBack += s.length; });
  g.setLineDash([]); g.strokeStyle = css("--short"); g.lineWidth = 1.5;
  shorts.forEach(([x, y]) => {
    g.beginPath(); g.moveTo(X(x) - 4, Y(y) - 4); g.lineTo(X(x) + 4, Y(y) + 4);
    g.moveTo(X(x) - 4, Y(y) + 4); g.lineTo(X(x) + 4, Y(y) - 4); g.stroke();
  });
  if (here) { const [x, y] = toWork(here); g.fillStyle = css("--ink"); g.beginPath(); g.arc(X(x), Y(y), 4, 0, 7); g.fill(); }
  c.dataset.plannedPoints = plannedCount;
  c.dataset.executedPoints = path.length;
  c.dataset.executedAs = exec.dry_run ? "dry-run" : "cut";
  c.dataset.executedSystem = exec.work_system || "";
  $("legend-dry").hidden = !exec.dry_run;
  c.dataset.turnBackPoints = turnBack;
  c.dataset.shortPoints = shorts.length;
  c.dataset.gridMm = step;
  c.dataset.preview = running ? "" : plannedFor || "";
  const s = $("strip");
  const [q, sw, sh] = sizeCanvas(s);
  const bw = sw / 600;
  strip.forEach((v, i) => {
    const x = sw - (strip.length - i) * bw;
    let y = sh;
    [["normal", "--normal"], ["arc", "--arc"], ["open", "--open"], ["short", "--short"]].forEach(([k, col]) => {
      const hh = v[k] * sh;
      q.fillStyle = getComputedStyle(document.body).getPropertyValue(col);
      q.globalAlpha = .35; q.fillRect(x, y - hh, bw + .5, hh); y -= hh;
    });
  });
  q.globalAlpha = 1; q.strokeStyle = "#1d232b"; q.lineWidth = 1.5; q.beginPath();
  strip.forEach((v, i) => {
    const x = sw - (strip.length - i) * bw, y = sh - 4 - v.feed / maxFeed * (sh - 8);
    i ? q.lineTo(x, y) : q.moveTo(x, y);
  });
  q.stroke();
  // The gap voltage, 0 to 100 V over the chart's height (gaps where the input reads none).
  q.strokeStyle = css("--accent"); q.lineWidth = 1; q.beginPath();
  let pen = false, voltsPoints = 0;
  strip.forEach((v, i) => {
    if (v.volts == null) { pen = false; return; }
    const x = sw - (strip.length - i) * bw, y = sh - 2 - Math.min(v.volts, 100) / 100 * (sh - 4);
    pen ? q.lineTo(x, y) : q.moveTo(x, y); pen = true; voltsPoints++;
  });
  q.stroke();
  s.dataset.voltsPoints = voltsPoints;
}

// The work offset table: every system's zero (machine mm), the active one marked; a row's
// Select makes it active (an MDI G5x line), touch-off writes into the system picked.
let offsetsShown = "";
function showOffsets(m) {
  const rows = m.work_offsets || [];
  const key = JSON.stringify([rows, m.work_system]);
  if (key === offsetsShown) return;
  offsetsShown = key;
  const t = $("offsets-table");
  t.innerHTML = `<tr><th>system</th>${axes.map((a) => `<th>${a}</th>`).join("")}<th></th></tr>`;
  rows.forEach((r) => {
    const tr = document.createElement("tr");
    if (r.system === m.work_system) tr.className = "active";
    tr.dataset.system = r.system;
    tr.innerHTML = `<td>${r.system}</td>${r.offset_mm.map((v) => `<td>${v.toFixed(4)}</td>`).join("")}` +
      `<td><button class="select-system" data-system="${r.system}">Select</button></td>`;
    t.appendChild(tr);
  });
  t.querySelectorAll("button.select-system").forEach((b) => {
    b.onclick = () => control("mdi", { line: b.dataset.system });
  });
}

