// What the operator does: jobs, programs and their editor, events, the token, commands,
// technology, upload, jog, homing; then the connection that keeps the page current.
// The job history: newest first, each pass's time.
let lastJobs = [];
async function loadJobs() {
  try {
    const r = await fetch("/api/jobs?count=50");
    lastJobs = (await r.json()).jobs || [];
  } catch (e) { return; }
  const t = $("jobs-table");
  t.innerHTML = "<tr><th>started</th><th>program</th><th>outcome</th><th>time</th><th>mm²/min</th><th>passes</th><th>shorts</th><th>wire breaks</th></tr>";
  lastJobs.forEach((j) => {
    const tr = document.createElement("tr");
    // Each pass: its time, its mean cut rate where the height is known, its wire breaks.
    const rate = (r) => (r != null ? r.toFixed(0) : null);
    const passes = (j.passes || []).map((p) => `${p.pass}${p.condition != null ? ` E${p.condition}` : ""}: ` +
      [fmtTime(p.time_s), rate(p.mean_rate_mm2_per_min) && `${rate(p.mean_rate_mm2_per_min)} mm²/min`,
       p.wire_breaks ? `${p.wire_breaks} break${p.wire_breaks > 1 ? "s" : ""}` : null].filter((x) => x).join(" ")).join(", ");
    const cells = [j.started, `${j.program}${j.dry_run ? " (dry run)" : ""}${j.from_line ? ` from line ${j.from_line}${j.from_pass ? ` in pass ${j.from_pass}` : ""}` : ""}${j.technology ? ` · ${j.technology}` : ""}`,
      j.outcome, fmtTime(j.machine_time_s), rate(j.mean_rate_mm2_per_min) || "–", passes || "–", j.shorts, j.wire_breaks];
    cells.forEach((c, i) => { const td = document.createElement("td"); td.textContent = c; if (i === 2 && c !== "done") td.className = "bad"; tr.appendChild(td); });
    t.appendChild(tr);
  });
  t.dataset.count = lastJobs.length;
}

// A program the check refused: its drawing is not shown as if it were fine, and the line
// the error names is marked in the listing.
let refusedLine = null;
function markRefused(program, error) {
  const m = /:(\d+):(\d+):/.exec(error || "");
  const name = (program || "").split("/").pop();
  planned = null; plannedFor = name; draw();
  refusedLine = m ? { program: name, line: Number(m[1]) } : null;
  listingFor = null;
  showListing(name, 0).then(applyRefused);
}
function applyRefused() {
  const ol = $("listing");
  ol.querySelectorAll("li.error").forEach((li) => li.classList.remove("error"));
  ol.dataset.errorLine = "";
  if (!refusedLine || listingFor !== refusedLine.program) return;
  const li = ol.children[refusedLine.line - 1];
  if (li) {
    li.classList.add("error");
    ol.dataset.errorLine = refusedLine.line;
    ol.scrollTop = Math.max(0, li.offsetTop - ol.offsetTop - ol.clientHeight / 3);
  }
}

// Editing a program on the page: its text in the editor; saved only if the whole of it
// reads (the daemon checks it as `edmd check` does), the refusal's line marked otherwise.
async function editProgram() {
  const name = $("program-list").value;
  if (!name) return;
  const r = await fetch(`/api/program?name=${encodeURIComponent(name)}`);
  const reply = await r.json();
  if (reply.truncated) { say(`${name} is too long to edit here`, true); return; }
  $("editor").value = (reply.lines || []).join("\n") + "\n";
  $("editor").dataset.program = name;
  $("editor").className = "on"; $("listing").style.display = "none";
  $("save").disabled = false; $("edit-cancel").disabled = false;
}
function closeEditor() {
  $("editor").className = ""; $("listing").style.display = "";
  $("save").disabled = true; $("edit-cancel").disabled = true;
}
async function saveProgram() {
  const name = $("editor").dataset.program;
  const t = token();
  if (!t) { login(true); say("log in first: saving needs the token", true); return; }
  const r = await fetch(`/api/programs?name=${encodeURIComponent(name)}&replace=true&check=true`,
    { method: "POST", body: $("editor").value, headers: { "Content-Type": "text/plain", "Authorization": `Bearer ${t}` } });
  const reply = await r.json().catch(() => ({ ok: false, error: r.statusText }));
  say(reply.ok ? reply.message : reply.error, !reply.ok);
  if (!reply.ok) {
    const m = /:(\d+):(\d+):/.exec(reply.error || "");
    if (m) {
      const line = Number(m[1]), ed = $("editor");
      const lines = ed.value.split("\n");
      const from = lines.slice(0, line - 1).join("\n").length + (line > 1 ? 1 : 0);
      ed.focus(); ed.setSelectionRange(from, from + (lines[line - 1] || "").length);
      ed.dataset.errorLine = line;
    }
    return;
  }
  $("editor").dataset.errorLine = "";
  closeEditor();
  refusedLine = null; listingFor = null; plannedFor = null;
  showListing(name, 0).then(applyRefused); loadPlanned(name);
}

async function loadPrograms() {
  try {
    const r = await fetch("/api/programs");
    const list = (await r.json()).programs;
    const sel = $("program-list");
    const keep = sel.value;
    sel.innerHTML = "";
    list.forEach((p) => { const o = document.createElement("option"); o.value = o.textContent = p.name; sel.appendChild(o); });
    if (keep) sel.value = keep;
    // Idle, the listing shows the program picked (a job's shows the job's).
    if (!listingFor) showListing(sel.value, 0);
  } catch (e) { say(`cannot list the programs: ${e}`, true); }
}

function say(text, bad) {
  text = forThePage(text);
  $("message").textContent = text; $("message").className = bad ? "error" : "";
  if (text) note(text, bad);
}

// The daemon words its replies for `edmd ctl` and the page alike; on the page a command is
// the control that gives it, never a shell command to type.
const CONTROLS = {
  resume: "Resume", rethread: "Rethread", reset: "Reset", discard: "Discard checkpoint",
  hold: "Hold", abort: "Abort", run: "Run", home: "Home",
};
function forThePage(text) {
  return String(text || "")
    .replace(new RegExp("\u0060edmd ctl ([a-z-]+)([^\u0060]*)\u0060", "g"), (all, command, args) => {
      if (command === "home" && args.includes("--here")) return "Home here";
      const control = CONTROLS[command];
      if (!control) return "the machine's terminal";
      if (command === "rethread" && args.includes("--here")) return "Rethread with “here” ticked";
      return args.includes("--force") ? `${control} (forced)` : control;
    })
    .replace(/--wire-at start-hole/g, "“wire at the start hole”")
    .replace(/--wire-at stopped/g, "“wire where the job stopped”")
    .replace(/--wire-at/g, "“wire stands”");
}

// The event list: what the page was told (replies, refusals with their file:line:col),
// newest first, then the job's own events from its recording (shorts, turn-backs, alarms,
// holds, conditions…), newest first.
const notes = [];
function note(text, bad) {
  notes.push({ at: new Date(), text, bad });
  if (notes.length > 50) notes.shift();
  showEvents();
}
const BAD_EVENTS = ["short", "alarm", "collision", "wire_break", "probe_missed", "abort", "starved"];
// An event as the list says it: its value read as what it is for that kind.
function eventText(e) {
  const v = e.depth;
  if (v == null) return e.kind.replace(/_/g, " ");
  switch (e.kind) {
    case "condition": return `condition E${v}`;
    case "pass": return `pass ${v}`;
    case "feed_override": case "rapid_override": return `${e.kind.replace(/_/g, " ")} ${v} %`;
    case "breakthrough": return v ? "breakthrough" : "no breakthrough";
    default: return `${e.kind.replace(/_/g, " ")} (${v} block${v === 1 ? "" : "s"})`;
  }
}
// One timeline, newest first: the page's notes at their time, the job's events at the job's
// start (as this page saw it) plus their machine time; a job whose start this page did not
// see lists its events first.
function showEvents() {
  const rows = notes.map((n) => ({ at: n.at.getTime(), t: 0, text: `${n.at.toLocaleTimeString()}  ${n.text}`, bad: n.bad }));
  if (executedPath) {
    const start = jobStartedAt && jobStartedAt.program === executedPath.program ? jobStartedAt.ms : null;
    executedPath.events.forEach((e) => {
      const at = start == null ? Infinity : start + e.t_s * 1000;
      rows.push({
        at, t: e.t_s, bad: BAD_EVENTS.includes(e.kind),
        text: `${start == null ? "" : `${new Date(at).toLocaleTimeString()}  `}t ${e.t_s.toFixed(3)} s  line ${e.line}  ${eventText(e)}`,
      });
    });
  }
  rows.sort((a, b) => (b.at - a.at) || (b.t - a.t));
  const ol = $("events");
  ol.innerHTML = "";
  rows.forEach((r) => { const li = document.createElement("li"); li.textContent = r.text; if (r.bad) li.className = "bad"; ol.appendChild(li); });
  ol.dataset.count = rows.length;
}

// The control token: typed or pasted into the login field (or taken from a link's `#token=`),
// kept in this browser.
function token() {
  const t = localStorage.getItem("edmd-token");
  return t ? t.trim() : null;
}
function login(ask) { $("login").className = ask ? "on" : ""; if (ask) $("token").focus(); }
$("login-save").onclick = () => {
  const t = $("token").value.trim();
  if (t) { localStorage.setItem("edmd-token", t); $("token").value = ""; login(false); say("logged in"); }
};
// A link's fragment: `#token=…`, or `#login=CODE` of `edmd ctl web-link`, whose code is traded
// for the token once. Taken at load and when a link is opened in a page already open.
function takeLink() {
  if (location.hash.startsWith("#token=")) {
    localStorage.setItem("edmd-token", decodeURIComponent(location.hash.slice(7)));
    history.replaceState(null, "", location.pathname);
    login(false);
  }
  if (location.hash.startsWith("#login=")) {
    const code = decodeURIComponent(location.hash.slice(7));
    history.replaceState(null, "", location.pathname);
    fetch("/api/login", { method: "POST", body: JSON.stringify({ code }), headers: { "Content-Type": "application/json" } })
      .then((r) => r.json())
      .then((reply) => {
        if (reply.ok) { localStorage.setItem("edmd-token", reply.token); login(false); say("logged in by the link"); }
        else { login(true); say(reply.error, true); }
      })
      .catch((e) => say(`cannot log in by the link: ${e}`, true));
  }
}
takeLink();
window.addEventListener("hashchange", takeLink);

async function control(cmd, body) {
  const t = token();
  if (!t) { login(true); say("log in first: control needs the token", true); return; }
  const r = await fetch(`/api/${cmd}`, { method: "POST", body: JSON.stringify(body || {}),
    headers: { "Content-Type": "application/json", "Authorization": `Bearer ${t}` } });
  const reply = await r.json().catch(() => ({ ok: false, error: r.statusText }));
  if (r.status === 401) { localStorage.removeItem("edmd-token"); login(true); say("the token was refused: log in again", true); return; }
  say(reply.ok ? reply.message : reply.error, !reply.ok);
  const check = reply.status && reply.status.check;
  if (reply.ok && check && !decided(check)) {
    awaitedCheck = check.id;
    // The verdict may have come before this reply: ask once; later ones come as events.
    fetch("/api/status").then((r) => r.json()).then((r) => r.status && show(r.status)).catch(() => {});
  }
  if (reply.status) show(reply.status);
}

$("run").onclick = () => {
  executedPath = null;
  const body = { program: $("program-list").value, dry_run: $("dry-run").checked };
  const from = Number($("from-line").value);
  if (from > 0) {
    body.from_line = from;
    if ($("approach").value) body.approach = $("approach").value;
    // Where the wire stands is the operator's word, never assumed: the daemon asks for it
    // on a run along the path and holds it to the stopped job's checkpoint.
    if ($("wire-at").value && $("approach").value !== "direct") body.wire_at = $("wire-at").value;
    // In a job in passes: the pass the line is cut in (the later ones are cut whole).
    const pass = Number($("from-pass").value);
    if (pass > 0) body.pass = pass;
  }
  const passes = Number($("passes").value);
  if (passes > 0) body.passes = passes;
  // The tab this job leaves (in passes), in place of the machine's wire.tab_mm.
  if ($("tab").value !== "") body.tab_mm = Number($("tab").value);
  const technology = techRequest();
  if (technology) body.technology = technology;
  control("run", body);
};

// Technology: the daemon's tables to pick from; the part height (a wire table) or the
// electrode area (a sinker table) makes the request, which Explain shows the choice of.
let techTables = [];
async function loadTechnology() {
  try {
    techTables = (await (await fetch("/api/technology")).json()).tables || [];
  } catch (e) { return; }
  const select = $("tech-table");
  while (select.options.length > 1) select.remove(1);
  techTables.forEach((t, i) => {
    const o = document.createElement("option");
    o.value = String(i);
    o.textContent = t.kind === "wire"
      ? `${t.material}, ${t.wire_mm} mm ${t.wire_type} (${t.heights_mm[0]}–${t.heights_mm[t.heights_mm.length - 1]} mm)${t.example ? " example" : ""}`
      : `${t.electrode} on ${t.material} (${t.areas_cm2[0][0]}–${t.areas_cm2[t.areas_cm2.length - 1][1]} cm²)${t.example ? " example" : ""}`;
    select.appendChild(o);
  });
  select.dataset.count = techTables.length;
}
function techRequest() {
  const t = techTables[Number($("tech-table").value)];
  if ($("tech-table").value === "" || !t) return null;
  const size = $("tech-size").value;
  return t.kind === "wire"
    ? `material=${t.material},height=${size},wire=${t.wire_mm},type=${t.wire_type}`
    : `electrode=${t.electrode},material=${t.material},area=${size}`;
}
$("tech-table").onchange = () => {
  const t = techTables[Number($("tech-table").value)];
  $("tech-size-label").textContent = t && t.kind === "sinker" ? "area cm²" : "height mm";
};
$("tech-explain").onclick = async () => {
  const out = $("tech-explained");
  const request = techRequest();
  out.hidden = false;
  if (!request) { out.className = ""; out.textContent = "pick a table (and the height or area) to see what it selects"; return; }
  const r = await (await fetch(`/api/technology?request=${encodeURIComponent(request)}`)).json();
  out.className = r.ok ? "" : "error";
  out.textContent = r.ok ? r.explain : r.error;
};
$("hold").onclick = () => control("hold");
$("resume").onclick = () => control("resume");
// Abort asks to be pressed again within 3 s (no dialog: a panel PC has no keyboard).
let abortArmed = null;
$("abort").onclick = () => {
  if (abortArmed) {
    clearTimeout(abortArmed); abortArmed = null;
    $("abort").textContent = "Abort"; $("abort").classList.remove("confirm");
    control("abort");
    return;
  }
  $("abort").textContent = "Confirm abort"; $("abort").classList.add("confirm");
  abortArmed = setTimeout(() => { abortArmed = null; $("abort").textContent = "Abort"; $("abort").classList.remove("confirm"); }, 3000);
};
// Discarding a checkpoint cannot be undone: pressed again within 3 s, as Abort.
let discardArmed = null;
$("discard").onclick = () => {
  if (discardArmed) {
    clearTimeout(discardArmed); discardArmed = null;
    $("discard").textContent = "Discard checkpoint"; $("discard").classList.remove("confirm");
    control("discard", { confirm: true });
    return;
  }
  $("discard").textContent = "Confirm discard"; $("discard").classList.add("confirm");
  discardArmed = setTimeout(() => { discardArmed = null; $("discard").textContent = "Discard checkpoint"; $("discard").classList.remove("confirm"); }, 3000);
};
$("feed-override").onchange = () => control("override", { kind: "feed", percent: Number($("feed-override").value) });
$("rapid-override").onchange = () => control("override", { kind: "rapid", percent: Number($("rapid-override").value) });
$("feed-override").oninput = () => { $("feed-override-value").textContent = `${$("feed-override").value} %`; };
$("rapid-override").oninput = () => { $("rapid-override-value").textContent = `${$("rapid-override").value} %`; };
// Upload: the file's text into the program directory, then picked in the list.
async function upload(name, text) {
  const t = token();
  if (!t) { login(true); say("log in first: uploading needs the token", true); return false; }
  const replace = $("upload-replace").checked ? "&replace=true" : "";
  const r = await fetch(`/api/programs?name=${encodeURIComponent(name)}${replace}`, { method: "POST", body: text,
    headers: { "Content-Type": "text/plain", "Authorization": `Bearer ${t}` } });
  const reply = await r.json().catch(() => ({ ok: false, error: r.statusText }));
  say(reply.ok ? reply.message : reply.error, !reply.ok);
  if (reply.ok) { await loadPrograms(); $("program-list").value = name; }
  return reply.ok;
}
// Jog: a step per press; held, a continuous jog renewed every 100 ms (the daemon stops it
// 250 ms after the last renewal: a closed tab or a lost link stops the axis).
$("jog-minus").onclick = () => control("jog", { axis: $("jog-axis").value, distance_mm: -Number($("jog-step").value) });
$("jog-plus").onclick = () => control("jog", { axis: $("jog-axis").value, distance_mm: Number($("jog-step").value) });
let jogTimer = null;
function jogHold(positive) {
  jogRelease();
  const renew = () => control("jog-continuous", { axis: $("jog-axis").value, positive });
  renew();
  jogTimer = setInterval(renew, 100);
}
function jogRelease() {
  if (jogTimer === null) return;
  clearInterval(jogTimer); jogTimer = null;
  control("jog-stop");
}
[["jog-hold-minus", false], ["jog-hold-plus", true]].forEach(([id, positive]) => {
  $(id).addEventListener("pointerdown", (e) => { e.preventDefault(); jogHold(positive); });
  ["pointerup", "pointerleave", "pointercancel"].forEach((ev) => $(id).addEventListener(ev, jogRelease));
});
window.addEventListener("blur", jogRelease);
$("mdi-send").onclick = () => { const line = $("mdi-line").value.trim(); if (line) control("mdi", { line }); };
$("mdi-line").addEventListener("keydown", (e) => { if (e.key === "Enter") $("mdi-send").click(); });
$("home-all").onclick = () => control("home", {});
// Home here: the axis picked, confirmed by a second press within 3 s (it moves the axis's
// coordinates, soft limits and offsets with it); the reply says by how much.
let homeArmed = null;
$("home-here").onclick = () => {
  const axis = $("jog-axis").value;
  if (homeArmed) {
    clearTimeout(homeArmed); homeArmed = null;
    $("home-here").textContent = "Home here"; $("home-here").classList.remove("confirm");
    control("home", { axes: [axis], here: true, force: true });
    return;
  }
  $("home-here").textContent = `Confirm: ${axis} is home here`; $("home-here").classList.add("confirm");
  homeArmed = setTimeout(() => { homeArmed = null; $("home-here").textContent = "Home here"; $("home-here").classList.remove("confirm"); }, 3000);
};
$("reset").onclick = () => control("reset");
$("edit").onclick = editProgram;
$("save").onclick = saveProgram;
$("edit-cancel").onclick = closeEditor;
$("touch-off").onclick = () => control("touch-off", { axis: $("jog-axis").value, value: Number($("touch-value").value), system: $("touch-system").value || undefined });
$("find").onclick = () => control("find", { target: $("find-target").value, system: $("find-system").value || undefined });
$("program-list").onchange = () => {
  const picked = $("program-list").value;
  const running = $("state").dataset.state !== "idle";
  const job = $("job").dataset.program || "";
  if (running) {
    // While a job runs: another program is opened beside it; its drawing stays the job's.
    browsing = job === picked || job.endsWith(`/${picked}`) ? null : picked;
    showListing(picked, 0);
    return;
  }
  showListing(picked, 0); loadPlanned(picked);
};
$("upload-file").onchange = async () => {
  const f = $("upload-file").files[0];
  if (f) await upload(f.name, await f.text());
  $("upload-file").value = "";
};
$("single-block").onchange = () => control("single-block", { on: $("single-block").checked });
$("rethread").onclick = () => control("rethread", { here: $("here").checked });
window.addEventListener("resize", draw);

function connect() {
  const events = new EventSource("/api/events");
  events.addEventListener("status", (e) => {
    $("link").textContent = `live ${new Date().toLocaleTimeString()}`;
    const reply = JSON.parse(e.data);
    if (reply.status) show(reply.status);
  });
  events.onerror = () => { $("link").textContent = "reconnecting…"; };
}

login(!token());
fetch("/api/status").then((r) => r.json()).then((r) => r.status && show(r.status)).catch(() => {});
loadPrograms();
loadExecuted();
loadJobs();
loadTechnology();
setInterval(loadPrograms, 30000);
connect();
