//! The history's and the counters' files, written, torn, refused and read back.

use super::file::CHUNK;
use super::*;
use std::io::Write;

#[test]
fn the_history_appends_and_lists_newest_first_and_the_counters_persist() {
    let dir = std::env::temp_dir().join(format!("edmd-history-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (jobs, counters) = (
        dir.join("state/jobs.jsonl"),
        dir.join("state/counters.json"),
    );
    let mut h = History::open(&jobs, &counters);
    let record = |program: &str| JobRecord {
        program: program.into(),
        started: local_time(),
        ended: local_time(),
        outcome: "done".into(),
        error: None,
        dry_run: false,
        from_line: None,
        from_pass: None,
        machine_time_s: 60.0,
        spark_s: Some(45.0),
        passes: vec![PassTime {
            pass: 1,
            condition: Some(4),
            row: Some("30 mm row".into()),
            time_s: 60.0,
            cut_mm: Some(30.0),
            mean_rate_mm2_per_min: Some(900.0),
            wire_breaks: 1,
        }],
        mean_rate_mm2_per_min: Some(900.0),
        technology: Some("material=steel height=30 wire=0.25 (…)".into()),
        shorts: 2,
        turn_backs: 2,
        wire_breaks: 0,
        breakthrough_mm: None,
        report: None,
    };
    h.add(Some(&record("a.nc")), 60.0, 50.0);
    h.add(None, 5.0, 0.0);
    h.add(Some(&record("b.nc")), 60.0, 40.0);
    assert_eq!(h.write_error, None);
    let (listed, bad) = h.last(10);
    assert_eq!(bad, 0);
    assert_eq!(
        listed
            .iter()
            .map(|r| r.program.as_str())
            .collect::<Vec<_>>(),
        ["b.nc", "a.nc"]
    );
    assert_eq!(listed[0].passes[0].condition, Some(4));
    assert_eq!(listed[0].passes[0].wire_breaks, 1);
    assert_eq!(listed[0].passes[0].mean_rate_mm2_per_min, Some(900.0));
    let table = table(&Page {
        jobs: listed.clone(),
        unreadable: Vec::new(),
        more: false,
    });
    assert!(
        table
            .contains("pass 1 E4  1 min 00 s  30.000 mm at 900 mm²/min, 1 wire break  (30 mm row)"),
        "{table}"
    );
    // A restart reads the counters back.
    let again = History::open(&jobs, &counters);
    assert_eq!(
        again.counters,
        HourCounters {
            jobs: 2,
            machine_s: 125.0,
            spark_s: 90.0
        }
    );
    assert_eq!(again.last(1).0.len(), 1);
    let _ = std::fs::remove_dir_all(&dir);
}

fn record(program: &str) -> JobRecord {
    JobRecord {
        program: program.into(),
        started: "2026-11-28 10:00:00".into(),
        ended: "2026-11-28 10:01:00".into(),
        outcome: "done".into(),
        error: None,
        dry_run: false,
        from_line: None,
        from_pass: None,
        machine_time_s: 60.0,
        spark_s: Some(50.0),
        passes: Vec::new(),
        mean_rate_mm2_per_min: None,
        technology: None,
        shorts: 0,
        turn_backs: 0,
        wire_breaks: 0,
        breakthrough_mm: None,
        report: None,
    }
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("edmd-history-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn programs(jobs: &[JobRecord]) -> Vec<&str> {
    jobs.iter().map(|j| j.program.as_str()).collect()
}

#[test]
fn a_torn_last_line_is_named_and_the_next_job_starts_a_line_of_its_own() {
    let dir = scratch("torn");
    let (path, counters) = (dir.join("jobs.jsonl"), dir.join("counters.json"));
    let mut h = History::open(&path, &counters);
    h.add(Some(&record("a.nc")), 60.0, 50.0);
    // A power cut in the middle of the next line.
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&path)
        .unwrap();
    f.write_all(br#"{"program":"torn.nc","started":"2026-11"#)
        .unwrap();
    drop(f);
    h.add(Some(&record("b.nc")), 60.0, 50.0);
    let page = h.file().page(0, 10).unwrap();
    assert_eq!(programs(&page.jobs), ["b.nc", "a.nc"]);
    assert_eq!(page.unreadable.len(), 1, "{:?}", page.unreadable);
    let torn_at = std::fs::read_to_string(&path)
        .unwrap()
        .find("{\"program\":\"torn")
        .unwrap();
    assert_eq!(
        page.unreadable[0],
        format!("byte {torn_at}: not a job (a torn line)")
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn pages_read_backwards_across_chunks_and_say_when_more_follow() {
    let dir = scratch("pages");
    let (path, counters) = (dir.join("jobs.jsonl"), dir.join("counters.json"));
    let mut h = History::open(&path, &counters);
    // Lines long enough that 300 of them span several of the reader's chunks.
    for i in 0..300 {
        let mut r = record(&format!("{i:03}-{}.nc", "x".repeat(400)));
        r.shorts = i;
        h.add(Some(&r), 1.0, 0.5);
    }
    assert!(std::fs::metadata(&path).unwrap().len() > 2 * CHUNK);
    let file = h.file();
    let first = file.page(0, 20).unwrap();
    assert_eq!(first.jobs.len(), 20);
    assert_eq!(first.jobs[0].shorts, 299);
    assert!(first.more);
    let middle = file.page(150, 100).unwrap();
    assert_eq!(
        middle.jobs.iter().map(|j| j.shorts).collect::<Vec<_>>(),
        (50..150).rev().collect::<Vec<_>>()
    );
    assert!(middle.more);
    let last = file.page(290, 50).unwrap();
    assert_eq!(last.jobs.len(), 10);
    assert!(!last.more);
    assert_eq!(file.page(400, 5).unwrap(), Page::default());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_line_that_cannot_be_written_is_kept_and_written_later_in_order() {
    let dir = scratch("retry");
    let (path, counters) = (dir.join("jobs.jsonl"), dir.join("counters.json"));
    let mut h = History::open(&path, &counters);
    h.add(Some(&record("a.nc")), 60.0, 50.0);
    // The history cannot be written: a directory stands where the file should be.
    std::fs::rename(&path, dir.join("aside")).unwrap();
    std::fs::create_dir(&path).unwrap();
    h.add(Some(&record("b.nc")), 60.0, 50.0);
    h.add(Some(&record("c.nc")), 60.0, 50.0);
    assert!(h.write_error.is_some());
    assert_eq!(h.counters.jobs, 3);
    std::fs::remove_dir(&path).unwrap();
    std::fs::rename(dir.join("aside"), &path).unwrap();
    h.retry();
    assert!(h.write_error.is_some(), "not before RETRY_EVERY");
    h.last_try = None;
    h.retry();
    assert_eq!(h.write_error, None);
    assert_eq!(programs(&h.last(10).0), ["c.nc", "b.nc", "a.nc"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn counters_that_do_not_read_are_kept_aside_and_rebuilt_from_the_history() {
    let dir = scratch("counters");
    let (path, counters) = (dir.join("jobs.jsonl"), dir.join("counters.json"));
    let mut h = History::open(&path, &counters);
    h.add(Some(&record("a.nc")), 60.0, 50.0);
    h.add(Some(&record("b.nc")), 60.0, 50.0);
    std::fs::write(&counters, "{\"jobs\": 2, \"machine_s\": 12").unwrap();
    let again = History::open(&path, &counters);
    assert_eq!(
        again.counters,
        HourCounters {
            jobs: 2,
            machine_s: 120.0,
            spark_s: 100.0
        }
    );
    let kept: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().into_string().unwrap())
        .filter(|n| n.starts_with("counters.json.bad-"))
        .collect();
    assert_eq!(kept.len(), 1, "{kept:?}");
    // A FIFO in the counters' place is no counters either, and no hang.
    let fifo = std::process::Command::new("mkfifo")
        .arg(&counters)
        .status()
        .unwrap();
    assert!(fifo.success());
    let third = History::open(&path, &counters);
    assert_eq!(third.counters.jobs, 2);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_fifo_in_the_history_s_place_is_an_error_at_once() {
    let dir = scratch("fifo");
    let (path, counters) = (dir.join("jobs.jsonl"), dir.join("counters.json"));
    let made = std::process::Command::new("mkfifo")
        .arg(&path)
        .status()
        .unwrap();
    assert!(made.success());
    let mut h = History::open(&path, &counters);
    h.add(Some(&record("a.nc")), 60.0, 50.0);
    assert!(
        h.write_error
            .as_deref()
            .unwrap()
            .contains("not a regular file")
    );
    assert!(h.file().page(0, 5).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_local_time_reads_as_a_date_and_a_clock() {
    let t = local_time();
    assert_eq!(t.len(), 19, "{t}");
    assert_eq!(&t[10..11], " ");
    assert_eq!(&t[13..14], ":");
}
