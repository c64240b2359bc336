//! The operator's console on the page, in headless Chromium through ChromeDriver: a
//! G41-first die run from its third contour line, the condition, pass n of N and wire
//! offset while passes run, the job in the history with each pass's time, a refused program
//! with its line marked and no drawing left, editing a program (checked before it is
//! saved), the work offset table, and Reset after a scripted E-stop with a red badge.
//! Skipped without Chromium unless `EDMD_WEB_TESTS=1` (CI), as `http.rs`'s page test.

use crate::common;
use crate::operator::{DIE, FAST_CONDITIONS, PASSES};

use std::path::Path;

use common::web::{Browser, Daemon, base64_decode, start, tool};
use serde_json::{Value, json};

fn wait(browser: &Browser, what: &str, script: &str) -> Value {
    browser.wait(what, script)
}

fn click(browser: &Browser, id: &str) {
    browser.press(id);
}

fn shot(browser: &Browser, path: &Path) {
    let png = browser.command("GET", "/screenshot", None);
    std::fs::write(path, base64_decode(png.as_str().unwrap())).unwrap();
}

/// Opens the page and logs in with the daemon's token.
fn open(d: &Daemon, chromedriver: &Path) -> Browser {
    let browser = Browser::start(chromedriver);
    browser.command("POST", "/url", Some(json!({"url": format!("{}/", d.base)})));
    wait(
        &browser,
        "the idle state",
        "return document.getElementById('state').textContent === 'idle'",
    );
    browser.eval(&format!(
        "document.getElementById('token').value = '{}'; document.getElementById('login-save').click(); return true",
        d.token
    ));
    wait(
        &browser,
        "the login",
        "return localStorage.getItem('edmd-token') !== null",
    );
    browser
}

/// Waits until the program list offers `program`.
fn listed(browser: &Browser, program: &str) {
    wait(
        browser,
        &format!("{program} listed"),
        &format!(
            "return Array.from(document.getElementById('program-list').options).some(o => o.value === '{program}')"
        ),
    );
}

fn pick(browser: &Browser, program: &str) {
    browser.eval(&format!(
        "const s = document.getElementById('program-list'); s.value = '{program}'; \
         s.dispatchEvent(new Event('change')); return s.value === '{program}'"
    ));
}

#[test]
fn the_operators_console_in_headless_chromium() {
    let Some(chromedriver) = tool("chromedriver") else {
        return;
    };
    let (d, dir) = start("console", &[PASSES, FAST_CONDITIONS]);
    std::fs::write(dir.join("programs/die.ngc"), DIE).unwrap();
    std::fs::write(dir.join("programs/far.nc"), "G21 G90\nG1 X900 F100\nM2\n").unwrap();
    let browser = open(&d, &chromedriver);
    listed(&browser, "die.ngc");
    // The G41-first die from its third contour line (line 6): accepted, run to its end.
    pick(&browser, "die.ngc");
    browser.eval("document.getElementById('from-line').value = '6'; return true");
    // Where the wire stands is asked, not assumed: refused until the operator says.
    click(&browser, "run");
    wait(
        &browser,
        "the question where the wire stands",
        "return document.getElementById('message').textContent.includes('say where that is')",
    );
    browser.eval("document.getElementById('wire-at').value = 'start-hole'; return true");
    click(&browser, "run");
    let s = d.wait_for("the run from line 6", |s| {
        s["job"]["from_line"]["line"] == 6
    });
    assert_eq!(s["job"]["from_line"]["approach"], "path");
    assert_eq!(s["job"]["from_line"]["wire_at"], "start-hole");
    d.wait_for("its end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    browser.eval("document.getElementById('from-line').value = ''; return true");
    // In three passes: the header shows the condition, the pass and the offset as they go.
    wait(
        &browser,
        "Run enabled",
        "return !document.getElementById('run').disabled",
    );
    browser.eval("document.getElementById('passes').value = '3'; return true");
    click(&browser, "run");
    let cutting = wait(
        &browser,
        "pass 2 of 3 in E3 at 0.135 mm",
        "const t = document.getElementById('cutting').textContent; \
         return t.includes('E3') && t.includes('pass 2 of 3') && t.includes('0.1350 mm') ? t : false",
    );
    eprintln!("cutting: {cutting}");
    shot(&browser, &dir.join("page-passes.png"));
    d.wait_for("the passes' end", |s| {
        s["state"] == "idle" && s["last_job"]["outcome"] == "done"
    });
    browser.eval("document.getElementById('passes').value = ''; return true");
    // The job history: the run in passes on top with each pass's time, the run from a line
    // under it; the hour counters.
    let row = wait(
        &browser,
        "the job in the history",
        "const t = document.getElementById('jobs-table'); \
         if (Number(t.dataset.count) < 2) return false; \
         const r = t.rows[1].textContent; \
         return r.includes('die.ngc') && r.includes('1 E4: ') && r.includes('2 E3: ') && r.includes('3 E1: ') ? r : false",
    );
    eprintln!("history: {row}");
    assert!(
        browser
            .eval("return document.getElementById('jobs-table').rows[2].textContent")
            .as_str()
            .unwrap()
            .contains("die.ngc from line 6")
    );
    wait(
        &browser,
        "the hour counters",
        "return document.getElementById('hours-jobs').textContent === 'jobs 2'",
    );
    // A refused program: its drawing goes, its line is marked in the listing.
    pick(&browser, "die.ngc");
    wait(
        &browser,
        "the die's preview",
        "return Number(document.getElementById('backplot').dataset.plannedPoints) > 5",
    );
    pick(&browser, "far.nc");
    click(&browser, "run");
    let refused = wait(
        &browser,
        "the refusal marked",
        "const ol = document.getElementById('listing'); const m = document.getElementById('message'); \
         const e = ol.querySelector('li.error'); \
         return m.className === 'error' && ol.dataset.errorLine === '2' && e && e.textContent.includes('X900') \
           && document.getElementById('backplot').dataset.plannedPoints === '0' ? m.textContent : false",
    );
    eprintln!("refused: {refused}");
    shot(&browser, &dir.join("page-refused.png"));
    // Editing: a bad line is not saved (the file keeps its text) and is selected in the
    // editor; the mended text is checked and saved.
    pick(&browser, "short.nc");
    wait(
        &browser,
        "short.nc listed",
        "return document.getElementById('listing-name').textContent.startsWith('short.nc')",
    );
    click(&browser, "edit");
    wait(
        &browser,
        "the editor",
        "return document.getElementById('editor').className === 'on' && document.getElementById('editor').value.includes('X0.2')",
    );
    browser.eval(
        "document.getElementById('editor').value = 'G21 G90\\nG1 X0.3 F60\\nG1 Q2\\nM2\\n'; \
         document.getElementById('save').click(); return true",
    );
    let bad = wait(
        &browser,
        "the edit refused",
        "const m = document.getElementById('message'); \
         return m.className === 'error' && m.textContent.includes('short.nc:3:') && \
           document.getElementById('editor').dataset.errorLine === '3' ? m.textContent : false",
    );
    eprintln!("edit refused: {bad}");
    let on_disk = || std::fs::read_to_string(dir.join("programs/short.nc")).unwrap();
    assert_eq!(on_disk(), "G21 G90\nG1 X0.2 F60\nM2\n");
    browser.eval(
        "document.getElementById('editor').value = 'G21 G90\\nG1 X0.3 F60\\nG1 Y0.1\\nM2\\n'; \
         document.getElementById('save').click(); return true",
    );
    wait(
        &browser,
        "the edit saved",
        "const m = document.getElementById('message'); \
         return m.className !== 'error' && m.textContent.includes('short.nc checked and saved') \
           && document.getElementById('editor').className === ''",
    );
    assert_eq!(on_disk(), "G21 G90\nG1 X0.3 F60\nG1 Y0.1\nM2\n");
    wait(
        &browser,
        "the saved text listed",
        "return document.getElementById('listing').textContent.includes('Y0.1')",
    );
    // An upload over an existing program is refused unless replace is ticked.
    let (code, reply) = d.call(
        "POST",
        "/api/programs?name=short.nc",
        Some(&d.token),
        Some("G1 X9\n"),
    );
    assert_eq!(code, 409, "{reply}");
    assert_eq!(on_disk(), "G21 G90\nG1 X0.3 F60\nG1 Y0.1\nM2\n");
    // The work offset table: touch off into G55, select it.
    browser.eval(
        "document.getElementById('touch-value').value = '1'; document.getElementById('touch-system').value = 'G55'; \
         document.getElementById('touch-off').click(); return true",
    );
    d.wait_for("the G55 offset", |s| {
        s["machine"]["work_offsets"][1]["system"] == "G55"
            && s["machine"]["work_offsets"][1]["offset_mm"][0] != 0.0
    });
    browser.eval(
        "document.querySelector('#offsets-table tr[data-system=\"G55\"] button').click(); return true",
    );
    d.wait_for("G55 active", |s| s["machine"]["work_system"] == "G55");
    wait(
        &browser,
        "G55 marked active",
        "return document.querySelector('#offsets-table tr.active').dataset.system === 'G55'",
    );
    shot(&browser, &dir.join("page-console.png"));
}

/// An E-stop on the page: a red badge (not idle's grey), and a Reset button that brings the
/// machine back once the E-stop is released.
#[test]
fn reset_after_an_estop_on_the_page() {
    let Some(chromedriver) = tool("chromedriver") else {
        return;
    };
    // The E-stop comes from the gap script at tick 4001 of the job.
    let dir = common::scratch("http", "console-estop");
    std::fs::write(dir.join("gap.txt"), "0 normal\n4001 estop\n").unwrap();
    let script = format!("gap.script=\"{}\"", dir.join("gap.txt").display());
    let (d, dir) = start("console-estop", &["gap.kind=\"script\"", &script]);
    std::fs::write(
        dir.join("programs/line.nc"),
        "G21 G90\nG1 X3 F600\nG1 Y1\nM2\n",
    )
    .unwrap();
    let browser = open(&d, &chromedriver);
    let grey =
        browser.eval("return getComputedStyle(document.getElementById('state')).backgroundColor");
    listed(&browser, "line.nc");
    assert!(
        browser
            .eval("return document.getElementById('reset').disabled")
            .as_bool()
            .unwrap(),
        "Reset is for a tripped machine only"
    );
    pick(&browser, "line.nc");
    click(&browser, "run");
    d.wait_for("the E-stop", |s| s["state"] == "estop");
    let red = wait(
        &browser,
        "the E-stop badge",
        "const s = document.getElementById('state'); \
         return s.dataset.state === 'estop' && !document.getElementById('reset').disabled \
           ? getComputedStyle(s).backgroundColor : false",
    );
    assert_ne!(red, grey, "the E-stop badge is not idle's colour");
    assert_eq!(red, json!("rgb(209, 36, 47)"), "the short's red");
    shot(&browser, &dir.join("page-estop.png"));
    click(&browser, "reset");
    d.wait_for("idle again", |s| s["state"] == "idle");
    wait(
        &browser,
        "idle on the page",
        "return document.getElementById('state').dataset.state === 'idle' && document.getElementById('reset').disabled",
    );
}

/// The run dialog's technology: the daemon's tables offered, what a height selects
/// explained (and a height outside the table refused with the nearest row), and a run with
/// it carries the technology into the job.
#[test]
fn the_run_dialog_picks_a_technology_and_explains_it() {
    let Some(chromedriver) = tool("chromedriver") else {
        return;
    };
    let tables = format!(
        "technology.dir=\"{}\"",
        common::repo().join("config/technology").display()
    );
    let (d, dir) = start("console-technology", &[&tables]);
    std::fs::write(dir.join("programs/die.ngc"), DIE).unwrap();
    let browser = open(&d, &chromedriver);
    wait(
        &browser,
        "the three example tables",
        "return document.getElementById('tech-table').dataset.count === '3'",
    );
    let pick_steel = "const s = document.getElementById('tech-table'); \
         const o = Array.from(s.options).find(o => o.textContent.startsWith('steel, 0.25 mm brass')); \
         s.value = o.value; s.dispatchEvent(new Event('change')); return o.textContent";
    let steel = browser.eval(pick_steel);
    assert!(
        steel.as_str().unwrap().contains("(10–60 mm) example"),
        "{steel}"
    );
    browser.eval("document.getElementById('tech-size').value = '32'; return true");
    click(&browser, "tech-explain");
    let explained = wait(
        &browser,
        "the explanation of 32 mm",
        "const e = document.getElementById('tech-explained'); \
         return !e.hidden && e.textContent.includes('between the rows 30 mm') ? e.textContent : false",
    );
    assert!(
        explained.as_str().unwrap().contains("E21        0.1786"),
        "{explained}"
    );
    shot(&browser, &dir.join("page-technology.png"));
    browser.eval("document.getElementById('tech-size').value = '75'; return true");
    click(&browser, "tech-explain");
    wait(
        &browser,
        "75 mm refused",
        "const e = document.getElementById('tech-explained'); \
         return e.className === 'error' && e.textContent.includes('the nearest row is 60 mm')",
    );
    // A dry run of the die with it: the job cuts the table's four passes with it.
    browser.eval("document.getElementById('tech-size').value = '32'; return true");
    listed(&browser, "die.ngc");
    pick(&browser, "die.ngc");
    browser.eval("document.getElementById('dry-run').checked = true; return true");
    click(&browser, "run");
    let s = d.wait_for("the job with its technology", |s| {
        s["job"]["technology"].is_string()
    });
    assert_eq!(
        s["job"]["technology"],
        "material=steel height=32 wire=0.25 type=brass (steel with 0.25 mm brass wire)"
    );
    assert_eq!(s["job"]["passes"], 4, "{s}");
    // A dry run is badged as one: it cuts nothing.
    wait(
        &browser,
        "the DRY RUN badge",
        "return !document.getElementById('dry-run-badge').hidden",
    );
    // Its path on the backplot is travel, not a cut.
    wait(
        &browser,
        "the dry run drawn as moved, not cut",
        "const c = document.getElementById('backplot'); \
         return c.dataset.executedAs === 'dry-run' && Number(c.dataset.executedPoints) > 1 \
         && !document.getElementById('legend-dry').hidden",
    );
    wait(
        &browser,
        "the technology in the header",
        "return document.getElementById('technology').textContent.includes('height=32')",
    );
    click(&browser, "abort");
    click(&browser, "abort");
    d.wait_for("the abort", |s| s["state"] == "idle");
}

/// The process on the page while the simulated gap cuts on its discharge model with the
/// adaptive law: the pulse rates by class, the ignition delay, the off time in force, the
/// estimated height and the cut rate, and the gap strip drawn from the pulse shares (arcs
/// among them); the job in the history with its mean cut rate.
#[test]
fn the_page_shows_the_process_as_the_pulses_tell_it() {
    let Some(chromedriver) = tool("chromedriver") else {
        return;
    };
    let (d, dir) = start(
        "console-process",
        &[
            "gap.kind=\"sim\"",
            "adaptive.enabled=true",
            "servo.law=\"voltage\"",
            "generator.condition=[{ number = 21, on_us = 8.0, off_us = 16.0, current_a = 12.0, \
             v_ref = 64.0, open_voltage_v = 90.0, wire_speed_m_per_min = 9.0, \
             flushing_bar = 12.0, feed_mm_per_min = 30.0, off_time_min_us = 5.0, \
             off_time_max_us = 60.0 }]",
        ],
    );
    std::fs::write(
        dir.join("programs/slot.ngc"),
        "G21 G90 G17\nE21\nG1 X3 F30\nM2\n",
    )
    .unwrap();
    let browser = open(&d, &chromedriver);
    listed(&browser, "slot.ngc");
    pick(&browser, "slot.ngc");
    click(&browser, "run");
    let row = wait(
        &browser,
        "the process row",
        "const p = document.getElementById('process'); \
         const t = p.textContent, h = document.getElementById('process-height'); \
         return Number(p.dataset.pulses) > 10000 && t.includes('normal') && t.includes('µs') \
           && h && h.textContent.includes(' mm') ? t : false",
    );
    eprintln!("process: {row}");
    let off: f64 = browser
        .eval("return document.getElementById('process-off-time').querySelector('b').textContent")
        .as_str()
        .unwrap()
        .trim_end_matches(" µs")
        .parse()
        .unwrap();
    assert!((5.0..=60.0).contains(&off), "{off} µs: within the bounds");
    // The strip draws the pulse shares: a normal, an arc, a short and an open share each.
    wait(
        &browser,
        "the strip from the pulses",
        "return strip.length > 3 && strip.every(v => Math.abs(v.normal + v.arc + v.short + v.open - 1) < 1e-9)",
    );
    browser.eval("document.getElementById('strip').scrollIntoView(); return true");
    shot(&browser, &dir.join("page-process.png"));
    click(&browser, "abort");
    click(&browser, "abort");
    d.wait_for("the abort", |s| s["state"] == "idle");
}

/// A pause M-code's message on the page, beside the state, while the job waits for it; gone
/// once the job goes on.
#[test]
fn a_pause_shows_its_message_on_the_page() {
    let Some(chromedriver) = tool("chromedriver") else {
        return;
    };
    let (d, dir) = start(
        "console-pause-message",
        &[
            "program.mcode=[{number=60, action=\"pause\", message=\"thread the wire, then resume\"}]",
        ],
    );
    std::fs::write(
        dir.join("programs/thread.ngc"),
        "G21 G90\nG1 X0.2 F300\nM60\nG1 Y0.2\nM2\n",
    )
    .unwrap();
    let browser = open(&d, &chromedriver);
    listed(&browser, "thread.ngc");
    pick(&browser, "thread.ngc");
    click(&browser, "run");
    let said = wait(
        &browser,
        "the pause's message",
        "const m = document.getElementById('pause-message'); \
         return !m.hidden && document.getElementById('state').dataset.state === 'paused' \
           ? m.textContent : false",
    );
    assert_eq!(said, "M60: thread the wire, then resume");
    shot(&browser, &dir.join("page-pause-message.png"));
    click(&browser, "resume");
    d.wait_for("the job's end", |s| s["state"] == "idle");
    wait(
        &browser,
        "the message gone",
        "return document.getElementById('pause-message').hidden",
    );
}

/// A stopped job's checkpoint on the page: Discard shows with it, asks to be pressed again,
/// then removes it.
#[test]
fn discard_on_the_page_asks_twice_and_removes_the_checkpoint() {
    let Some(chromedriver) = tool("chromedriver") else {
        return;
    };
    let (d, _dir) = start("console-discard", &[]);
    let (code, _) = d.post("/api/run", r#"{"program": "runtime-path.nc"}"#);
    assert_eq!(code, 200);
    d.wait_for("moving", |s| s["state"] == "running");
    d.post("/api/hold", "{}");
    d.wait_for("held", |s| s["state"] == "held");
    d.post("/api/abort", "{}");
    let s = d.wait_for("the checkpoint", |s| {
        s["state"] == "idle" && s["checkpoint"]["resumable"] == true
    });
    let browser = open(&d, &chromedriver);
    wait(
        &browser,
        "Discard shown",
        "return !document.getElementById('discard').hidden",
    );
    click(&browser, "discard");
    wait(
        &browser,
        "the confirmation",
        "return document.getElementById('discard').textContent === 'Confirm discard'",
    );
    assert_eq!(
        d.status()["checkpoint"],
        s["checkpoint"],
        "one press discards nothing"
    );
    click(&browser, "discard");
    d.wait_for("no checkpoint", |s| s.get("checkpoint").is_none());
    wait(
        &browser,
        "Discard hidden",
        "return document.getElementById('discard').hidden",
    );
}

/// A program in G55 (its offset set by the program itself): while it runs the DRO reads in
/// G55 and the backplot draws the executed path in G55's coordinates, on the program's
/// drawing; the machine's own system is G54 all the while.
#[test]
fn the_dro_and_the_backplot_are_in_the_programs_work_system() {
    let Some(chromedriver) = tool("chromedriver") else {
        return;
    };
    let (d, dir) = start("console-g55", &[]);
    std::fs::write(
        dir.join("programs/g55.nc"),
        "G21 G90\nG10 L2 P2 X2 Y0\nG55\nG1 X1 Y0 F60\nG1 X1 Y1\nM2\n",
    )
    .unwrap();
    let browser = open(&d, &chromedriver);
    listed(&browser, "g55.nc");
    pick(&browser, "g55.nc");
    click(&browser, "run");
    let s = d.wait_for("the move in G55", |s| {
        s["state"] == "running"
            && s["machine"]["position_machine_mm"][0]
                .as_f64()
                .unwrap_or(0.0)
                > 2.5
    });
    assert_eq!(s["machine"]["work_system"], "G55", "{s}");
    let (m, w) = (
        s["machine"]["position_machine_mm"][0].as_f64().unwrap(),
        s["machine"]["position_work_mm"][0].as_f64().unwrap(),
    );
    assert!(
        (m - w - 2.0).abs() < 1e-9,
        "work = machine − G55's X2: {m} {w}"
    );
    wait(
        &browser,
        "the DRO in G55",
        "return document.getElementById('position-work').textContent.startsWith('work G55')",
    );
    // The executed path, drawn in G55: the cut's X on the drawing is the program's (≤ 1 mm),
    // not the machine's (up to 3 mm).
    let x_max = wait(
        &browser,
        "the path drawn in G55",
        "const c = document.getElementById('backplot'); \
         if (c.dataset.executedSystem !== 'G55' || !executedPath || executedPath.path.length < 2) return false; \
         const xs = executedPath.path.map((p) => p[0] - executedPath.work_offset_mm[0]); \
         return Math.max(...xs);",
    );
    assert!(x_max.as_f64().unwrap() <= 1.0 + 1e-6, "{x_max}");
    d.wait_for("its end", |s| s["state"] == "idle");
    // The daemon's words name ctl's commands; the page names its own controls instead.
    let said = browser.eval(
        "return forThePage('thread the wire where it broke, then `edmd ctl resume`; home first \
         (`edmd ctl home --here` …); `edmd ctl resume --force` continues it; run with \
         --wire-at stopped; `edmd ctl web-link`')",
    );
    assert_eq!(
        said.as_str().unwrap(),
        "thread the wire where it broke, then Resume; home first (Home here …); Resume \
         (forced) continues it; run with “wire where the job stopped”; the machine's terminal"
    );
    // A refusal on the page, in the page's words: a run from a line without saying where
    // the wire stands.
    browser.eval("document.getElementById('from-line').value = '4'; return true");
    click(&browser, "run");
    let body = wait(
        &browser,
        "the refusal",
        "return document.getElementById('message').className === 'error' ? document.body.innerText : false",
    );
    let body = body.as_str().unwrap();
    assert!(
        body.contains("say where that is. “wire at the start hole”"),
        "{body}"
    );
    assert!(
        !body.contains("edmd ") && !body.contains("--wire-at"),
        "{body}"
    );
}

/// While a job runs, another program is opened on the page, edited, checked and saved; the
/// listing stays on it as the status comes in; the running program's Save is refused and its
/// file kept.
#[test]
fn while_a_job_runs_another_program_is_opened_edited_and_saved_on_the_page() {
    let Some(chromedriver) = tool("chromedriver") else {
        return;
    };
    let (d, dir) = start("console-background", &[]);
    std::fs::write(dir.join("programs/long.nc"), "G21 G90\nG1 X6 F60\nM2\n").unwrap();
    std::fs::write(dir.join("programs/other.nc"), "G21 G90\nG1 X1 F60\nM2\n").unwrap();
    let browser = open(&d, &chromedriver);
    listed(&browser, "other.nc");
    pick(&browser, "long.nc");
    click(&browser, "run");
    d.wait_for("running", |s| s["state"] == "running");
    wait(
        &browser,
        "the job's listing",
        "return document.getElementById('listing-name').textContent === 'long.nc'",
    );
    pick(&browser, "other.nc");
    wait(
        &browser,
        "the other program's listing",
        "return document.getElementById('listing-name').textContent === 'other.nc' \
         && document.getElementById('listing').textContent.includes('G1 X1 F60')",
    );
    // Several statuses later it is still the one shown and picked.
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let shown = browser.eval(
        "return [document.getElementById('listing-name').textContent, document.getElementById('program-list').value]",
    );
    assert_eq!(shown, json!(["other.nc", "other.nc"]));
    click(&browser, "edit");
    browser.eval(
        "const e = document.getElementById('editor'); e.value = e.value.replace('X1', 'X2'); return true",
    );
    click(&browser, "save");
    wait(
        &browser,
        "the save",
        "return document.getElementById('listing').textContent.includes('G1 X2 F60')",
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("programs/other.nc")).unwrap(),
        "G21 G90\nG1 X2 F60\nM2\n"
    );
    assert_eq!(d.status()["state"], "running", "the job ran on");
    // The running program: its Save is refused, its file kept.
    pick(&browser, "long.nc");
    click(&browser, "edit");
    browser.eval(
        "const e = document.getElementById('editor'); e.value = e.value.replace('X6', 'X7'); return true",
    );
    click(&browser, "save");
    wait(
        &browser,
        "the refusal",
        "return document.getElementById('message').className === 'error' \
         && document.getElementById('message').textContent.includes('the running job')",
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("programs/long.nc")).unwrap(),
        "G21 G90\nG1 X6 F60\nM2\n"
    );
    click(&browser, "abort");
    click(&browser, "abort");
    d.wait_for("idle", |s| s["state"] == "idle");
}
