// The status as the page shows it: the DRO, the state, the program listing, the controls
// the operator may press now.
"use strict";
const $ = (id) => document.getElementById(id);
const strip = [];         // {normal, arc, open, short (shares), feed, volts}
let planned = null, plannedFor = null, lastGap = null, lastPulses = null, maxFeed = 1, axes = ["X", "Y"];
// The executed path as the daemon recorded it (GET /api/executed), where the electrode is,
// and what turns machine coordinates into the work coordinates the plot is drawn in.
let executedPath = null, executedAt = 0, executedBusy = false, wasRunning = false;
let here = null, workOffset = [0, 0], travel = [null, null];
// When the running job started, in this browser's clock (its machine time counted back).
let jobStartedAt = null;
// Another program the operator opened while a job runs (read, edited, checked, saved: the
// job's own is the daemon's to refuse); `null`: the listing follows the job.
let browsing = null;

function fmtTime(s) {
  if (s == null) return "–";
  s = Math.round(s);
  const h = Math.floor(s / 3600), m = Math.floor(s / 60) % 60, r = s % 60;
  return h ? `${h} h ${m} min` : m ? `${m} min ${r} s` : `${r} s`;
}

function show(status) {
  const state = status.state;
  // A pause says why (a tab's "secure the slug" is the operator's cue).
  $("state").textContent = status.job && status.job.pause ? `${state}: ${status.job.pause}` : state;
  $("state").dataset.state = state;
  const j = status.job;
  // A dry run is told apart from a cut at a glance.
  $("dry-run-badge").hidden = !(j && j.dry_run);
  // What the program tells the operator at this stop ("M60: thread the wire …").
  $("pause-message").textContent = j && j.pause_message ? j.pause_message : "";
  $("pause-message").hidden = !(j && j.pause_message);
  axes = status.axes;
  $("job").textContent = j ? `${j.program} line ${j.line}` : "no job";
  $("job").dataset.program = j ? j.program : "";
  // What is cutting now: the condition, the pass of the technology table, the wire offset.
  $("technology").textContent = j && j.technology ? j.technology : "";
  $("technology").title = j && j.generator ? Object.entries(j.generator).map(([k, v]) => `${k} ${v}`).join(", ") : "";
  $("cutting").textContent = j ? [j.condition != null ? `E${j.condition}` : null,
    j.pass != null ? `pass ${j.pass} of ${j.passes}` : null,
    j.wire_offset ? `${j.wire_offset.side} ${j.wire_offset.mm.toFixed(4)} mm` : null]
    .filter((x) => x).join(" · ") : "";
  // The DRO: work coordinates large, machine coordinates under them, always; an axis not
  // homed is marked "?". In inches while the program reads in inches (G20).
  const m = status.machine;
  const inch = !!(j && j.inch), unit = inch ? 25.4 : 1, digits = inch ? 5 : 4;
  $("units").textContent = inch ? "in (the program's G20)" : "mm";
  const dro = (id, label, pos) => {
    $(id).innerHTML = "";
    const head = document.createElement("span");
    head.className = "kv dro-head";
    head.textContent = label;
    $(id).appendChild(head);
    status.axes.forEach((a, i) => {
      const span = document.createElement("span");
      const homed = m.homed[i];
      span.className = homed ? "kv" : "kv unhomed";
      span.title = homed ? "" : "not homed: the position is only believed";
      span.innerHTML = `${a}${homed ? "" : "?"} <b>${pos[i] != null ? (pos[i] / unit).toFixed(digits) : "–"}</b>`;
      $(id).appendChild(span);
    });
  };
  dro("position-machine", "machine", m.position_machine_mm);
  dro("position-work", `work ${m.work_system}`, m.position_work_mm);
  $("feed").textContent = j ? j.feed_mm_per_min.toFixed(2) : "–";
  $("servo").textContent = j ? j.servo : "–";
  const p = j ? j.progress : 0;
  $("bar").firstElementChild.style.width = `${(p * 100).toFixed(1)}%`;
  $("progress").textContent = j ? `${(p * 100).toFixed(1)} %` : "–";
  $("eta").textContent = j ? fmtTime(j.eta_s) : "–";
  // The gap voltage where the input measures one (the simulator, an ADC), live.
  $("gap-volts").textContent = j && j.gap_volts != null ? `${j.gap_volts.toFixed(1)} V` : "–";
  $("to-go").textContent = j ? `${((j.path_total_mm - j.path_done_mm) / unit).toFixed(inch ? 4 : 3)} ${inch ? "in" : "mm"}` : "–";
  showOffsets(m);
  const h = status.hours || { jobs: 0, machine_s: 0, spark_s: 0 };
  $("hours").innerHTML = [["machine", fmtTime(h.machine_s)],
    ["sparking", fmtTime(h.spark_s)], ["jobs", h.jobs]]
    .map(([k, v]) => `<span class="kv" id="hours-${k}">${k} <b>${v}</b></span>`).join("") +
    `<span class="kv">(the machine's life)</span>`;
  const c = status.counters;
  $("counters").innerHTML = [["shorts", c.shorts], ["turn-backs", c.turn_backs],
    ["alarms", c.alarms], ["holds", c.holds], ["jumps", c.jumps], ["wire breaks", c.wire_breaks],
    ["overruns", c.overruns]].map(([k, v]) => `<span class="kv" id="count-${k.replace(" ", "-")}">${k} <b>${v}</b></span>`).join("");
  const mm = m.position_machine_mm, wm = m.position_work_mm;
  workOffset = [0, 1].map((i) => (mm[i] != null && wm[i] != null ? mm[i] - wm[i] : 0));
  travel = [0, 1].map((i) => (m.travel_mm ? m.travel_mm[i] : null));
  here = mm.length > 1 && mm[0] != null ? [mm[0], mm[1]] : null;
  if (j) {
    jobStartedAt = { program: j.program, ms: Date.now() - j.machine_time_s * 1000 };
    // The list shows the running program (a page opened mid-job picks it too).
    const sel = $("program-list");
    const mine = Array.from(sel.options).find((o) => j.program === o.value || j.program.endsWith(`/${o.value}`));
    if (mine && document.activeElement !== sel && !browsing) sel.value = mine.value;
    if (plannedFor !== j.program) loadPlanned(j.program);
    maxFeed = Math.max(maxFeed, j.feed_mm_per_min);
    if (Date.now() - executedAt > 1000) loadExecuted();
  } else {
    // Idle: the program picked is previewed; the last job's path once more, complete.
    if (wasRunning) loadExecuted();
    const picked = $("program-list").value;
    if (picked && plannedFor !== picked && state === "idle") loadPlanned(picked);
  }
  if (wasRunning && !j) browsing = null;
  if (wasRunning && !j) {
    // A job ended: its line in the history; a reply about it ("running mdi …") is stale.
    loadJobs();
    if ($("message").className !== "error") $("message").textContent = "";
  }
  wasRunning = !!j;
  // The strip: each status's share of pulses by class where the gap counts them (the
  // simulator, a discriminator through HAL), else its share of ticks by gap state.
  const pr = j && j.process;
  const pulses = pr ? [pr.pulses.normal, pr.pulses.arc, pr.pulses.short, pr.pulses.open] : null;
  const live = { feed: j ? j.feed_mm_per_min : 0, volts: j && j.gap_volts != null ? j.gap_volts : null };
  if (pulses && lastPulses) {
    const d = pulses.map((v, i) => v - lastPulses[i]);
    const n = d[0] + d[1] + d[2] + d[3];
    if (n > 0) strip.push({ normal: d[0] / n, arc: d[1] / n, short: d[2] / n, open: d[3] / n, ...live });
  } else if (!pulses && lastGap) {
    const d = c.gap_ticks.map((v, i) => v - lastGap[i]);
    const n = d[0] + d[1] + d[2];
    if (n > 0) strip.push({ normal: d[0] / n, arc: 0, open: d[1] / n, short: d[2] / n, ...live });
  }
  if (strip.length > 600) strip.shift();
  lastGap = c.gap_ticks;
  lastPulses = pulses;
  showProcess(pr);
  showControls(status);
  // The listing follows the job, unless the operator opened another program meanwhile.
  const followed = j && !browsing;
  showListing(followed ? j.program : $("program-list").value, followed ? j.line : 0);
  draw();
}

// The process as the pulses tell it: rates by class, the mean ignition delay, the off time
// in force, the estimated height and the cut rate.
function showProcess(pr) {
  const el = $("process");
  if (!pr) { el.innerHTML = ""; el.dataset.pulses = "0"; return; }
  const r = pr.rates_hz, k = (v) => (v >= 1000 ? `${(v / 1000).toFixed(1)} k` : v.toFixed(0));
  const figures = [["normal", `${k(r.normal)}/s`], ["arc", `${k(r.arc)}/s`], ["short", `${k(r.short)}/s`],
    ["open", `${k(r.open)}/s`],
    ["ignition delay", pr.mean_ignition_delay_us != null ? `${pr.mean_ignition_delay_us.toFixed(1)} µs` : "–"],
    ["off time", `${pr.off_time_us.toFixed(1)} µs`],
    ["height", pr.height_estimate_mm != null ? `${pr.height_estimate_mm.toFixed(1)} mm` : "–"],
    ["cut rate", pr.cut_rate_mm2_per_min != null ? `${pr.cut_rate_mm2_per_min.toFixed(0)} mm²/min` : "–"]];
  el.innerHTML = figures.map(([name, v]) => `<span class="kv" id="process-${name.replace(" ", "-")}">${name} <b>${v}</b></span>`).join("");
  const p = pr.pulses;
  el.dataset.pulses = p.normal + p.arc + p.short + p.open;
}

// The program's listing, the line in hand highlighted and kept in view (the list scrolls,
// not the page).
let listingFor = null, listingLoading = false;
async function showListing(program, line) {
  if (program && program !== listingFor && !listingLoading) {
    listingLoading = true;
    try {
      const r = await fetch(`/api/program?name=${encodeURIComponent(program)}`);
      const reply = await r.json();
      const ol = $("listing");
      ol.innerHTML = "";
      (reply.lines || []).forEach((text) => {
        const li = document.createElement("li"); li.textContent = text || " "; ol.appendChild(li);
      });
      ol.dataset.lines = (reply.lines || []).length;
      $("listing-name").textContent = `${program.split("/").pop()}${reply.truncated ? " (first lines)" : ""}`;
      listingFor = program;
      applyRefused();
    } catch (e) { /* the listing stays as it was */ }
    listingLoading = false;
  }
  const ol = $("listing");
  const old = ol.querySelector("li.current");
  const now = line > 0 ? ol.children[line - 1] : null;
  if (old !== now) {
    if (old) old.classList.remove("current");
    if (now) {
      now.classList.add("current");
      const top = now.offsetTop - ol.offsetTop;
      if (top < ol.scrollTop || top > ol.scrollTop + ol.clientHeight - now.offsetHeight) {
        ol.scrollTop = Math.max(0, top - ol.clientHeight / 3);
      }
    }
    ol.dataset.current = line;
  }
}

// What the operator may do now, what the last check and job said, what can be resumed.
function showControls(status) {
  const st = status.state, j = status.job, cp = status.checkpoint;
  const sel = $("jog-axis");
  if (sel.options.length !== status.axes.length) {
    sel.innerHTML = "";
    status.axes.forEach((a) => { const o = document.createElement("option"); o.value = o.textContent = a; sel.appendChild(o); });
  }
  const manual = st === "idle" || st === "limit";
  ["jog-minus", "jog-plus", "mdi-send", "home-all", "home-here", "touch-off", "find"].forEach((id) => { $(id).disabled = !manual; });
  $("reset").disabled = !(st === "estop" || st === "limit");
  document.querySelectorAll("button.select-system").forEach((b) => { b.disabled = !manual; });
  const f = status.machine.find;
  $("find-result").textContent = f ? forThePage(`find ${f.id} ${f.state}: ${f.message}`) : "";
  $("find-result").className = f && f.state === "failed" ? "kv error" : "kv";
  ["jog-hold-minus", "jog-hold-plus"].forEach((id) => { $(id).disabled = !(manual || st === "jogging"); });
  const moving = ["running", "mdi", "jogging", "homing", "finding", "rethreading"].includes(st);
  const idle = st === "idle";
  $("run").disabled = !idle;
  $("hold").disabled = !moving;
  $("resume").disabled = !(["held", "paused", "threading"].includes(st) || (idle && cp && cp.resumable));
  $("abort").disabled = idle && !(status.check && !decided(status.check));
  $("rethread").disabled = st !== "wire-break";
  const check = status.check;
  // The verdict of the check this page asked for replaces "accepted: checking …".
  if (check && decided(check) && check.id === awaitedCheck) {
    awaitedCheck = null;
    if (check.phase === "refused") { say(`refused: ${check.error}`, true); markRefused(check.program, check.error); }
    else say(check.message || "started");
  }
  const last = status.last_job;
  const dry = last && lastJobs.length && lastJobs[0].program === last.program && lastJobs[0].dry_run;
  $("outcome").textContent = last
    ? forThePage(`last job: ${last.program}: ${last.outcome}${dry ? " (dry run: nothing was cut)" : ""}${last.error ? ` (${last.error})` : ""}`) : "";
  $("outcome").className = last && last.outcome !== "done" && last.outcome !== "stopped" ? "error" : "";
  const kept = status.kept_checkpoint;
  $("resumable").textContent = (cp && cp.resumable
    ? `checkpoint: ${cp.program} line ${cp.line} (${cp.reason}): Resume continues it` : "")
    + (kept ? `${cp && cp.resumable ? "; " : ""}kept aside: ${kept.program} line ${kept.line}, the checkpoint again once no other is` : "");
  $("discard").hidden = !(cp && cp.resumable);
  const o = status.overrides || { feed_pct: 100, rapid_pct: 100 };
  if (document.activeElement !== $("feed-override")) $("feed-override").value = o.feed_pct;
  if (document.activeElement !== $("rapid-override")) $("rapid-override").value = o.rapid_pct;
  $("feed-override-value").textContent = `${o.feed_pct} %`;
  $("rapid-override-value").textContent = `${o.rapid_pct} %`;
  $("single-block").checked = !!status.single_block;
  const overruns = j ? j.overruns : 0;
  $("warning").className = overruns > 0 ? "on" : "";
  $("warning").textContent = overruns > 0
    ? `${overruns} overruns: ticks started late, so the pulse timing of this job was not kept ` +
      `(steps are not lost, but the speed wavered): the machine's real-time setup needs checking ` +
      `(the operator's guide, "Real-time").` : "";
}

function decided(check) { return check.phase === "started" || check.phase === "refused"; }
let awaitedCheck = null;

async function loadPlanned(program) {
  plannedFor = program;
  try {
    const r = await fetch(`/api/path?program=${encodeURIComponent(program)}`);
    // A program that does not read has no drawing: not the last one under its name.
    planned = r.ok ? await r.json() : null;
  } catch (e) { /* the backplot goes on with the executed path alone */ }
  draw();
}

