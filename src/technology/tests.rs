use std::path::Path;

use super::*;

const STEEL: &str = include_str!("../../config/technology/wire-steel-brass-0.25.toml");
const ALUMINIUM: &str = include_str!("../../config/technology/wire-aluminium-brass-0.25.toml");
const COPPER: &str = include_str!("../../config/technology/sinker-copper-steel.toml");

/// The shipped example tables.
fn shipped() -> Tables {
    let tables = [
        (STEEL, "steel.toml"),
        (ALUMINIUM, "aluminium.toml"),
        (COPPER, "copper.toml"),
    ]
    .iter()
    .map(|(text, name)| parse(text, name).unwrap())
    .collect();
    Tables::new(Path::new("tech"), tables).unwrap()
}

fn ask(text: &str) -> Request {
    Request::parse(text, "--technology", 1, 1).unwrap()
}

fn refused(text: &str) -> String {
    shipped().select(&ask(text)).unwrap_err().to_string()
}

#[test]
fn a_height_on_a_row_is_that_row() {
    let s = shipped()
        .select(&ask("material=steel,height=30,wire=0.25"))
        .unwrap();
    let passes = s.wire_passes();
    assert_eq!(passes.len(), 4);
    assert_eq!(
        passes.iter().map(|p| p.condition).collect::<Vec<_>>(),
        [21, 22, 23, 24]
    );
    assert_eq!(passes[0].offset_mm, 0.178);
    assert_eq!(passes[0].feed_mm_per_min, Some(3.6));
    assert!(passes[1].reverse && !passes[2].reverse);
    // The pass's feed is its condition's sparking feed, its corner control the condition's.
    let e21 = &s.conditions[0];
    assert_eq!((e21.number, e21.feed_mm_per_min), (21, 3.6));
    assert_eq!(e21.corner.unwrap().distance_mm, 0.5);
    assert_eq!(e21.generator.on_time_us, 8.0);
    assert_eq!(e21.generator.flushing_bar, 12.0);
    assert!(
        s.why[0].contains("the row 30 mm (steel.toml:"),
        "{:?}",
        s.why
    );
    assert_eq!(s.pass_rows()[0], "30 mm row");
}

#[test]
fn a_height_between_rows_interpolates_offsets_and_feeds_of_the_same_passes() {
    let s = shipped()
        .select(&ask("material=steel height=32 wire=0.25"))
        .unwrap();
    let p = s.wire_passes();
    // 20 % of the way from the 30 to the 40 mm row.
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
    assert!(
        close(p[0].offset_mm, 0.178 + 0.2 * (0.181 - 0.178)),
        "{p:?}"
    );
    assert!(close(
        p[0].feed_mm_per_min.unwrap(),
        3.6 + 0.2 * (2.9 - 3.6)
    ));
    assert!(close(p[3].offset_mm, 0.128));
    assert!(close(
        s.conditions[1].feed_mm_per_min,
        7.5 + 0.2 * (6.2 - 7.5)
    ));
    assert!(s.why[0].contains("between the rows 30 mm"), "{:?}", s.why);
    assert_eq!(s.pass_rows()[0], "32 mm, between the 30 and 40 mm rows");
    // Between 40 and 60 mm the rough cut changes condition (E25 only in the 60 mm row): it is
    // the thicker row's as written, the skims in both rows are interpolated.
    let s = shipped()
        .select(&ask("material=steel height=50 wire=0.25"))
        .unwrap();
    let p = s.wire_passes();
    assert_eq!((p[0].condition, p[0].offset_mm), (25, 0.185));
    assert_eq!(p[0].feed_mm_per_min, Some(2.0));
    assert!(close(p[1].offset_mm, 0.141), "{p:?}");
    assert!(s.pass_rows()[0].contains("E25 is not in the 40 mm row"));
    let explain = s.explain();
    assert!(explain.contains("EXAMPLE"), "{explain}");
    assert!(
        explain.contains("E25: on 8 µs, off 16 µs, peak 12 A"),
        "{explain}"
    );
}

#[test]
fn a_request_outside_the_table_is_refused_naming_the_nearest_rows() {
    let e = refused("material=steel height=80 wire=0.25");
    assert!(e.contains("height 80 mm is outside"), "{e}");
    assert!(e.contains("the nearest row is 60 mm (steel.toml:"), "{e}");
    let e = refused("material=steel height=5 wire=0.25");
    assert!(e.contains("the nearest row is 10 mm"), "{e}");
    let e = refused("material=steel height=30 wire=0.3");
    assert!(e.contains("no steel table for 0.3 mm wire"), "{e}");
    assert!(
        e.contains("steel with 0.25 mm brass wire (steel.toml)"),
        "{e}"
    );
    let e = refused("material=titanium height=30 wire=0.25");
    assert!(e.contains("no wire table for material \"titanium\""), "{e}");
    assert!(e.contains("aluminium with 0.25 mm brass"), "{e}");
    let e = refused("electrode=copper material=steel area=40");
    assert!(e.contains("4 to 16 cm²"), "{e}");
    let e = refused("electrode=graphite material=steel area=4");
    assert!(e.contains("copper on steel"), "{e}");
}

#[test]
fn a_sinker_request_takes_the_row_of_its_area_and_sets_orbits_and_jumps() {
    let s = shipped()
        .select(&ask("electrode=copper,material=steel,area=6"))
        .unwrap();
    assert_eq!(s.stages.len(), 4);
    assert!(s.wire_passes().is_empty());
    let e43 = s.conditions.iter().find(|c| c.number == 43).unwrap();
    assert_eq!(e43.orbit_radius_mm, Some(0.35));
    assert_eq!(
        (e43.jump_interval_s, e43.jump_height_mm),
        (Some(1.2), Some(1.0))
    );
    assert_eq!(e43.feed_mm_per_min, 0.3);
    let mut config = Config::default();
    s.apply(&mut config);
    let orbit = config.sinker.orbit.for_condition(43);
    assert_eq!(orbit.radius_mm, 0.35);
    // The shipped machine orbits in no shape: a stage with a radius orbits in a circle.
    assert_eq!(orbit.shape, crate::vocab::OrbitShape::Circle);
    assert!(config.conditions.iter().any(|c| c.number == 41));
    // The wire's own passes stay: a sinker table has none.
    assert_eq!(config.wire.passes, Config::default().wire.passes);
}

#[test]
fn applying_a_wire_selection_replaces_the_passes_and_same_numbered_conditions() {
    let s = shipped()
        .select(&ask("material=aluminium height=30 wire=0.25"))
        .unwrap();
    let mut config = Config::default();
    config.conditions[0].number = 31;
    s.apply(&mut config);
    assert_eq!(config.wire.passes, s.wire_passes());
    let e31: Vec<_> = config
        .conditions
        .iter()
        .filter(|c| c.number == 31)
        .collect();
    assert_eq!(e31.len(), 1);
    assert_eq!(e31[0].feed_mm_per_min, 8.0);
    assert_eq!(e31[0].generator.servo_ref_v, 26.0);
    assert_eq!(config.wire.diameter_mm, 0.25);
}

#[test]
fn requests_read_with_commas_or_spaces_and_mistakes_are_located() {
    assert_eq!(
        ask("material=steel, height=32 , wire=0.25,type=brass"),
        Request::Wire {
            material: "steel".into(),
            height_mm: 32.0,
            wire_mm: 0.25,
            wire_type: Some("brass".into()),
        }
    );
    let e = |t: &str| Request::parse(t, "p.ngc", 3, 7).unwrap_err().to_string();
    assert_eq!(
        e("material=steel hieght=3"),
        "p.ngc:3:22: technology: \"hieght\" is not a technology key (material, height (mm), \
         wire (mm), type (the wire's); or electrode, material, area (cm²))"
    );
    assert!(
        e("material=steel height=-3 wire=0.25").starts_with("p.ngc:3:29:"),
        "{}",
        e("material=steel height=-3 wire=0.25")
    );
    assert!(e("material=steel height=3").contains("does not say the wire diameter"));
    assert!(e("material=steel height=3 wire=0.2 area=3").contains("not both"));
    assert!(e("material=a material=b").contains("material is given twice"));
}

#[test]
fn the_header_comment_is_read_until_the_first_block() {
    let text = "%\n(die 12, customer 4711)\n  (TECH material=steel height=32 wire=0.25)\nG21\n";
    let r = header_of(text, "die.ngc").unwrap().unwrap();
    assert_eq!(r.text(), "material=steel height=32 wire=0.25");
    assert_eq!(
        header_of("G21\n(TECH material=steel)\n", "p").unwrap(),
        None
    );
    let e = header_of("(tech: material=steel height=x wire=1)\n", "p.ngc")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("p.ngc:1:"), "{e}");
    assert!(e.contains("height=x"), "{e}");
}

#[test]
fn table_mistakes_are_located_in_their_file() {
    let bad = STEEL.replace(
        "feed_mm_per_min = 14.0, reverse",
        "feed_mm_per_min = -1.0, reverse",
    );
    let e = parse(&bad, "t.toml").unwrap_err().to_string();
    assert!(e.starts_with("t.toml:88:3:"), "{e}");
    assert!(e.contains("pass 2: feed_mm_per_min = -1"), "{e}");
    let bad = STEEL.replace(
        "condition = 23, feed_mm_per_min = 18.0",
        "condition = 29, feed_mm_per_min = 18.0",
    );
    let e = parse(&bad, "t.toml").unwrap_err().to_string();
    assert!(
        e.contains(
            "condition = 29 is not one of this table's [[condition]] (E21, E22, E23, E24, E25)"
        ),
        "{e}"
    );
    let bad = STEEL.replace("height_mm = 20.0", "height_mm = 5.0");
    let e = parse(&bad, "t.toml").unwrap_err().to_string();
    assert!(e.contains("rows go by rising height"), "{e}");
    let bad = STEEL.replace("number = 22\n", "number = 22\nfeed_mm_per_min = 3.0\n");
    let e = parse(&bad, "t.toml").unwrap_err().to_string();
    assert!(e.contains("a wire table's feeds are its passes'"), "{e}");
    let bad = STEEL.replace("open_voltage_v = 90.0\n", "open_voltage = 90.0\n");
    let e = parse(&bad, "t.toml").unwrap_err().to_string();
    assert!(e.starts_with("t.toml:"), "{e}");
    assert!(e.contains("open_voltage"), "{e}");
    let bad = COPPER.replace("orbit_radius_mm = 0.08", "orbit_radius_mm = 0.28");
    let e = parse(&bad, "c.toml").unwrap_err().to_string();
    assert!(e.contains("the orbit would cut past size"), "{e}");
    // Two tables for one material and wire.
    let twice = vec![
        parse(STEEL, "a.toml").unwrap(),
        parse(STEEL, "b.toml").unwrap(),
    ];
    let e = Tables::new(Path::new("t"), twice).unwrap_err().to_string();
    assert!(e.starts_with("b.toml: the same material and wire"), "{e}");
}

#[test]
fn a_table_file_that_cannot_be_read_is_an_error_never_skipped() {
    let dir = std::env::temp_dir().join(format!("edmd-tables-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("steel.toml"), STEEL).unwrap();
    std::fs::write(dir.join("notes.txt"), "not a table").unwrap();
    assert_eq!(Tables::load(&dir).unwrap().tables().len(), 1);
    // A link to nothing: an error naming it, not "no tables".
    std::os::unix::fs::symlink(dir.join("gone.toml"), dir.join("aluminium.toml")).unwrap();
    let e = Tables::load(&dir).unwrap_err().to_string();
    assert!(e.contains("aluminium.toml"), "{e}");
    std::fs::remove_file(dir.join("aluminium.toml")).unwrap();
    // A FIFO: refused at once, never waited on.
    let made = std::process::Command::new("mkfifo")
        .arg(dir.join("copper.TOML"))
        .status()
        .unwrap();
    assert!(made.success());
    let e = Tables::load(&dir).unwrap_err().to_string();
    assert!(e.contains("copper.TOML") && e.contains("FIFO"), "{e}");
    // The folder missing: no tables.
    assert!(
        Tables::load(&dir.join("nothing"))
            .unwrap()
            .tables()
            .is_empty()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_header_past_its_bound_is_refused_at_its_line_and_one_within_is_read() {
    let dir = std::env::temp_dir().join(format!("edmd-header-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let long = dir.join("long.ngc");
    let note = "(note)\n";
    let within = note.repeat(100_000);
    std::fs::write(
        &long,
        format!("{within}(TECH material=steel height=32 wire=0.25)\nG1 X1\n"),
    )
    .unwrap();
    let r = header(&long, "long.ngc").unwrap().unwrap();
    assert_eq!(r.text(), "material=steel height=32 wire=0.25");
    let past = note.repeat(200_000);
    std::fs::write(
        &long,
        format!("{past}(TECH material=steel height=32 wire=0.25)\nG1 X1\n"),
    )
    .unwrap();
    let e = header(&long, "long.ngc").unwrap_err().to_string();
    let lines = super::request::HEADER_BYTES as usize / note.len();
    assert!(e.starts_with(&format!("long.ngc:{lines}:1:")), "{e}");
    assert!(e.contains("runs past 1024 KiB"), "{e}");
    // A short program of comments only: no request, no error.
    std::fs::write(&long, "(only a note)\n").unwrap();
    assert!(header(&long, "long.ngc").unwrap().is_none());
    let _ = std::fs::remove_dir_all(&dir);
}
