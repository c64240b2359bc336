use super::overrides::line_col;
use super::*;

fn load(text: &str, overrides: &[&str]) -> Result<Config, String> {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    Config::from_toml_str(text, "edmd.toml", &overrides).map_err(|e| e.to_string())
}

#[test]
fn shipped_default_is_valid_and_matches_design() {
    let c = Config::default();
    assert_eq!(c.machine.axes, vec![Axis::X, Axis::Y]);
    assert_eq!(c.machine.step_mm, vec![0.001, 0.001]);
    assert_eq!(c.interpolation.predictor, Predictor::Taylor);
    assert_eq!(c.interpolation.segmentation, Segmentation::Chord);
    assert_eq!(c.buffer.capacity, 1024);
    assert_eq!(c.buffer.reserved, 256);
    assert_eq!(c.fine.tick.us(), 50);
    assert!(c.fine.virtual_time);
    assert_eq!(c.output.kind, OutputKind::Sim);
    assert_eq!(c.gap.kind, GapKind::Sim);
    assert_eq!(c.daemon.socket, PathBuf::from("/run/edmd/edmd.sock"));
}

#[test]
fn a_byte_order_mark_is_skipped() {
    let c = load("\u{feff}[buffer]\ncapacity = 64\nreserved = 8\n", &[]).unwrap();
    assert_eq!(c.buffer.capacity, 64);
}

#[test]
fn every_default_key_is_commented_in_the_shipped_file() {
    // Each `key = value` line is preceded by a comment line (possibly a run of them).
    let lines: Vec<&str> = DEFAULT_CONFIG_TOML.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') || t.starts_with('[') {
            continue;
        }
        assert!(
            i > 0 && lines[i - 1].trim().starts_with('#'),
            "line {} `{t}` has no comment above it",
            i + 1
        );
    }
}

#[test]
fn a_partial_file_keeps_the_other_defaults() {
    let c = load("[buffer]\ncapacity = 64\nreserved = 16\n", &[]).unwrap();
    assert_eq!(c.buffer.capacity, 64);
    assert_eq!(c.machine, Config::default().machine);
}

#[test]
fn unknown_key_is_named_with_its_line() {
    let err = load("[buffer]\ncapacity = 64\ncapcity = 3\n", &[]).unwrap_err();
    assert!(
        err.starts_with("edmd.toml:3:1: unknown key `capcity` in [buffer]"),
        "{err}"
    );
    let err = load("\n[bufer]\n", &[]).unwrap_err();
    assert!(
        err.starts_with("edmd.toml:2:2: unknown section [bufer]"),
        "{err}"
    );
}

#[test]
fn validation_errors_point_at_the_key() {
    let err = load("[buffer]\ncapacity = 100\nreserved = 100\n", &[]).unwrap_err();
    assert!(
        err.starts_with("edmd.toml:3:1: buffer.reserved: must be at least 0 and less than"),
        "{err}"
    );
    let err = load("[machine]\nstep_mm = [0.001, 0.0]\n", &[]).unwrap_err();
    assert!(
        err.starts_with("edmd.toml:2:1: machine.step_mm: must be greater than 0 and at most 10 mm"),
        "{err}"
    );
    // Absurd magnitudes: refused with the unit, and printed as written, not in 300 digits.
    let err = load("[interpolation]\nchord_tolerance_mm = 1e300\n", &[]).unwrap_err();
    assert_eq!(
        err,
        "edmd.toml:2:1: interpolation.chord_tolerance_mm: must be greater than 0 and at most \
         10 mm, got 1e300"
    );
    let err = load("[interpolation]\nchord_tolerance_mm = -1\n", &[]).unwrap_err();
    assert!(
        err.contains("edmd.toml:2:1: interpolation.chord_tolerance_mm"),
        "{err}"
    );
    let err = load("[machine]\naxes = [\"X\", \"Q\"]\nstep_mm = [1, 1]\n", &[]).unwrap_err();
    assert!(err.contains("\"Q\" is not an axis"), "{err}");
    let err = load("[machine]\naxes = [\"X\", \"Y\", \"Z\"]\n", &[]).unwrap_err();
    assert!(
        err.contains("machine.step_mm: has 2 values but machine.axes has 3"),
        "{err}"
    );
}

#[test]
fn type_errors_and_bad_enum_values_are_located() {
    let err = load("[buffer]\ncapacity = \"big\"\n", &[]).unwrap_err();
    assert!(
        err.starts_with("edmd.toml:2:1: buffer.capacity: invalid type"),
        "{err}"
    );
    let err = load("[interpolation]\npredictor = \"adams\"\n", &[]).unwrap_err();
    assert!(
        err.contains("edmd.toml:2:1: interpolation.predictor: unknown variant `adams`"),
        "{err}"
    );
}

#[test]
fn syntax_errors_carry_line_and_column() {
    let err = load("[buffer]\ncapacity = = 3\n", &[]).unwrap_err();
    assert!(err.starts_with("edmd.toml:2:"), "{err}");
}

#[test]
fn overrides_apply_in_order_and_are_validated() {
    let c = load(
        "",
        &[
            "buffer.capacity=64",
            "buffer.reserved=8",
            "output.kind=file",
            "machine.axes=[\"X\",\"Y\",\"Z\"]",
            "machine.step_mm=[0.001,0.001,0.0005]",
            "buffer.capacity=128",
        ],
    )
    .unwrap();
    assert_eq!(c.buffer.capacity, 128);
    assert_eq!(c.output.kind, OutputKind::File);
    assert_eq!(c.machine.axes.len(), 3);
    let err = load("", &["buffer.reserved=5000"]).unwrap_err();
    assert!(
        err.starts_with("--set buffer.reserved=5000: buffer.reserved"),
        "{err}"
    );
    let err = load("", &["buffer.size=5"]).unwrap_err();
    assert!(err.contains("unknown key `size` in [buffer]"), "{err}");
    let err = load("", &["capacity=5"]).unwrap_err();
    assert!(err.contains("not of the form section.key"), "{err}");
    let err = load("", &["fine.tick_us=fast"]).unwrap_err();
    assert!(
        err.starts_with("--set fine.tick_us=fast: fine.tick_us: invalid type"),
        "{err}"
    );
}

#[test]
fn cross_key_rules() {
    let err = load("[output]\nkind = \"parport\"\n", &[]).unwrap_err();
    assert!(err.contains("fine.virtual_time: must be false"), "{err}");
    let err = load("[gap]\nkind = \"parport\"\n", &[]).unwrap_err();
    assert!(err.contains("gap.kind"), "{err}");
    // Steps in bursts are for a pulse file or a simulated machine, never for drives.
    let port = "[output]\nkind = \"parport\"\n[fine]\nvirtual_time = false\n";
    let err = load(port, &["fine.ticks_per_wake=10"]).unwrap_err();
    assert!(err.contains("fine.ticks_per_wake: must be 1"), "{err}");
    assert_eq!(load(port, &[]).unwrap().fine.ticks_per_wake, 1);
    let file = load("[output]\nkind = \"file\"\n", &["fine.ticks_per_wake=10"]);
    assert_eq!(file.unwrap().fine.ticks_per_wake, 10);
    let err = load("", &["fine.ticks_per_wake=0"]).unwrap_err();
    assert!(err.contains("fine.ticks_per_wake"), "{err}");
}

#[test]
fn parport_pins_and_timing_are_checked() {
    const PORT: &str = "[output]\nkind = \"parport\"\n[fine]\nvirtual_time = false\n";
    let c = load(PORT, &[]).unwrap();
    assert_eq!(c.parport.step_pins, [2, 4, 6, 8]);
    assert_eq!(c.parport.dir_pins, [3, 5, 7, 9]);
    assert_eq!(
        (c.parport.short_pin, c.parport.open_pin),
        (Some(10), Some(11))
    );
    assert_eq!(c.parport.enable_pin, None);
    let err = |text: &str, sets: &[&str]| load(text, sets).unwrap_err();
    assert!(
        err("[parport]\ninvert_pins = [20]\n", &[]).contains("20 is not a signal pin"),
        "ground pins cannot be inverted"
    );
    assert!(err("[parport]\ninvert_pins = [2, 2]\n", &[]).contains("pin 2 is listed twice"));
    assert!(
        err("[parport]\nenable_pin = 9\n", &[])
            .contains("parport.enable_pin: pin 9 is already used by parport.dir_pins")
    );
    assert!(err("[parport]\nopen_pin = 10\n", &[]).contains("already used by parport.short_pin"));
    assert!(err("[parport]\nstep_length_ns = 0\n", &[]).contains("parport.step_length_ns"));
    // Axis count and timing only matter when the port is in use.
    let four_axes = [
        "machine.axes=[\"X\",\"Y\",\"Z\",\"A\",\"B\"]",
        "machine.step_mm=[0.001,0.001,0.001,0.001,0.001]",
    ];
    load("", &four_axes).unwrap();
    let e = err(PORT, &four_axes);
    assert!(
        e.contains("parport.step_pins: has 4 pins but machine.axes has 5 axes"),
        "{e}"
    );
    load("", &["fine.tick_us=10"]).unwrap();
    let e = err(PORT, &["fine.tick_us=40"]);
    assert!(e.contains("raise fine.tick_us to at least 45"), "{e}");
    let e = err(
        "[output]\nkind = \"parport\"\n[fine]\nvirtual_time = false\n[gap]\nkind = \"parport\"\n",
        &["parport.short_pin=0", "parport.open_pin=0"],
    );
    assert!(
        e.contains("needs parport.short_pin or parport.open_pin"),
        "{e}"
    );
}

#[test]
fn line_col_counts_characters() {
    assert_eq!(line_col("ab\ncµd", 6), (2, 3));
    assert_eq!(line_col("ab\ncµd", 5), (2, 2)); // inside µ: rounds down, no panic
    assert_eq!(line_col("", 0), (1, 1));
}

#[test]
fn the_shipped_defaults_hand_down_what_the_lower_floors_unit_tests_assume() {
    // sim's unit tests build their settings by hand, from these same defaults.
    let c = Config::default();
    let mut shipped = crate::sim::SimSettings::from_config(&c);
    // The discharge model's constants are its own tests' (`sim::discharge::tests::params`);
    // the gap's other tests run on the kinematic model.
    assert_eq!(
        shipped.params.model,
        crate::sim::SimModel::Discharge(Box::new(crate::sim::discharge::tests::params()))
    );
    shipped.params.model = crate::sim::SimModel::Kinematic;
    assert_eq!(shipped, crate::sim::tests::settings(&[]));
    let fine = crate::fine::FineSettings::from_config(&c);
    assert_eq!(fine.dt, c.fine.tick.secs());
    assert_eq!(fine.feeds.normal, c.servo.normal_feed_mm_per_min / 60.0);
    // A reader without a configuration tapers with the shipped guides.
    let (reader, shipped) = (
        crate::gcode::ProgramOptions::default(),
        crate::gcode::ProgramOptions::from_config(&c),
    );
    assert_eq!(
        (reader.guides, reader.thickness_mm),
        (shipped.guides, shipped.thickness_mm)
    );
}

#[test]
fn generator_conditions_as_tables_replace_the_shipped_list() {
    let c = load(
        "[[generator.condition]]\nnumber = 7\non_us = 3.0\noff_us = 9.0\ncurrent_a = 4.0\n\
         v_ref = 28.0\nfeed_mm_per_min = 40.0\n",
        &[],
    )
    .unwrap();
    assert_eq!(c.conditions.len(), 1);
    assert_eq!(
        (
            c.conditions[0].number,
            c.conditions[0].generator.servo_ref_v
        ),
        (7, 28.0)
    );
    assert_eq!(
        Config::default().conditions.len(),
        6,
        "E1-E5 and E9 (touch) shipped"
    );
    let e = load(
        "[[generator.condition]]\nnumber = 2\non_us = 1.0\noff_us = 1.0\ncurrent_a = 1.0\n\
         v_ref = 1.0\nfeed_mm_per_min = 1.0\n[[generator.condition]]\nnumber = 2\non_us = 1.0\n\
         off_us = 1.0\ncurrent_a = 1.0\nv_ref = 1.0\nfeed_mm_per_min = 1.0\n",
        &[],
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("E2 is defined twice"), "{e}");
}

#[test]
fn the_three_state_law_may_be_spelled_state() {
    let c = Config::load(None, &["servo.law=\"state\"".to_string()]).unwrap();
    assert_eq!(c.servo.law, ServoLaw::ThreeState);
}

#[test]
fn homing_axes_are_checked_and_ordered_by_sequence() {
    const PORT: &str = "[output]\nkind = \"parport\"\n[fine]\nvirtual_time = false\n";
    // "auto": required on a real machine, not on the simulated one.
    assert!(!Config::default().homing.required);
    assert!(load(PORT, &[]).unwrap().homing.required);
    assert!(
        !load(PORT, &["homing.required=false"])
            .unwrap()
            .homing
            .required
    );
    let e = load("", &["homing.required=\"maybe\""]).unwrap_err();
    assert!(e.contains("true, false or \"auto\""), "{e}");
    // The shipped entries: X then Y (sequence 0, 1), the simulator's switches at home.
    let c = Config::default();
    let order: Vec<Axis> = c.homing.axes.iter().map(|h| h.axis).collect();
    assert_eq!(order, [Axis::X, Axis::Y]);
    assert_eq!(c.homing.axes[0].search_distance_mm, 500.0);
    assert_eq!(c.sim.home_switch_mm, [None, None]);
    let axis = |fields: &str| {
        format!(
            "homing.axis=[{{axis=\"X\", direction=\"+\", search_feed_mm_per_min=600.0, latch_feed_mm_per_min=30.0, home_position_mm=10.0{fields}}}]"
        )
    };
    let e = load("", &[&axis(", final_move_mm=2.0")]).unwrap_err();
    assert!(e.contains("runs into the switch"), "{e}");
    let e = load("", &[&axis(", switch_pin=2")]).unwrap_err();
    assert!(e.contains("switch_pin = 2: not an input pin"), "{e}");
    let e = load(PORT, &[&axis(", switch_pin=10")]).unwrap_err();
    assert!(
        e.contains("switch_pin = 10 is already used by parport."),
        "{e}"
    );
    let e = load(
        "",
        &[&axis(", latch_feed_mm_per_min=900.0").replace("latch_feed_mm_per_min=30.0, ", "")],
    )
    .unwrap_err();
    assert!(e.contains("at most the search feed"), "{e}");
    // A switch pin is read only from the port.
    let e = load("", &[&axis(", switch_pin=15")]).unwrap_err();
    assert!(
        e.contains("switch_pin = 15: nothing reads the parallel port's inputs"),
        "{e}"
    );
    let c = load(PORT, &[&axis(", switch_pin=15, sequence=3")]).unwrap();
    assert_eq!(c.homing.axes[0].switch_pin, Some(15));
    let c = load(
        "",
        &[&axis(", sequence=3"), "sim.home_switch_mm={X=3.0,Z=1.0}"],
    )
    .unwrap();
    assert_eq!(c.sim.home_switch_mm, [Some(3.0), None]);
    let e = load("", &["sim.home_switch_mm={Q=1.0}"]).unwrap_err();
    assert!(e.contains("\"Q\" is not an axis letter"), "{e}");
}

#[test]
fn the_orbit_table_overlays_key_by_key_and_conditions_carry_their_own() {
    use crate::vocab::OrbitShape;
    let c = load(
        "[sinker.orbit]\nshape = \"circle\"\n\n[[generator.condition]]\nnumber = 3\n\
         on_us = 4.0\noff_us = 8.0\ncurrent_a = 5.0\nv_ref = 25.0\nfeed_mm_per_min = 60.0\n\
         orbit_radius_mm = 0.25\n",
        &["sinker.orbit.feed_mm_per_min=90"],
    )
    .unwrap();
    let o = &c.sinker.orbit;
    // The file's shape, the shipped radius and expansion, the override's feed.
    assert_eq!(
        (o.default.shape, o.default.radius_mm),
        (OrbitShape::Circle, 0.1)
    );
    assert!(o.expand);
    assert_eq!(o.feed_mm_per_min, 90.0);
    // E3 keeps the shape and finishes to its own radius.
    assert_eq!(o.for_condition(3).radius_mm, 0.25);
    assert_eq!(o.for_condition(3).shape, OrbitShape::Circle);
    assert_eq!(o.for_condition(1).radius_mm, 0.1);
    let e = load("[sinker.orbit]\nshape = \"spiral\"\n", &[]).unwrap_err();
    assert!(
        e.contains("\"spiral\" is not an orbit shape: none, circle"),
        "{e}"
    );
    let e = load("[sinker.orbit]\nradius = 1.0\n", &[]).unwrap_err();
    assert!(e.contains("unknown key `radius` in [sinker.orbit]"), "{e}");
    let e = load("", &["sinker.orbit.pitch=1"]).unwrap_err();
    assert!(e.contains("--set sinker.orbit.pitch=1"), "{e}");
}

#[test]
fn a_max_feed_above_one_step_per_tick_is_accepted_with_the_real_limit() {
    let c = load("", &[]).unwrap();
    let w = max_feed_warning(&c).expect("18000 mm/min is above 1 µm per 50 µs");
    assert!(w.contains("is 1200 mm/min on X"), "{w}");
    let c = load("", &["machine.max_feed_mm_per_min=1200"]).unwrap();
    assert_eq!(max_feed_warning(&c), None);
    // The slowest axis names the limit.
    let c = load("", &["machine.step_mm=[0.001, 0.0005]"]).unwrap();
    assert!(max_feed_warning(&c).unwrap().contains("600 mm/min on Y"));
}

#[test]
fn the_turn_back_settings_default_and_refuse_with_their_keys() {
    let c = load("", &[]).unwrap();
    // 0: the machine's largest acceleration (the normal one in the shipped file).
    assert_eq!(c.servo.reverse_accel_mm_per_s2, 4900.0);
    assert_eq!(c.servo.short_confirm_ticks, 1);
    assert!((c.servo.min_retract_mm - 0.005).abs() < 1e-12);
    let c = load("[servo]\nreverse_accel_mm_per_s2 = 800.0\n", &[]).unwrap();
    assert_eq!(c.servo.reverse_accel_mm_per_s2, 800.0);
    let err = load("[servo]\nshort_confirm_ticks = 0\n", &[]).unwrap_err();
    assert!(
        err.contains("edmd.toml:2:") && err.contains("servo.short_confirm_ticks"),
        "{err}"
    );
    let err = load("", &["servo.min_retract_um=-1"]).unwrap_err();
    assert!(err.contains("servo.min_retract_um"), "{err}");
    // The sim's old per-job count is refused, the keys listed with what replaced it.
    let err = load("[sim]\ndebris_shorts = 5\n", &[]).unwrap_err();
    assert!(
        err.contains("edmd.toml:2:1: unknown key `debris_shorts`")
            && err.contains("debris_shorts_per_mm"),
        "{err}"
    );
}

#[test]
fn machine_builders_m_codes_are_checked_with_their_line() {
    let c = load(
        "[[program.mcode]]\nnumber = 60\naction = \"pause\"\nmessage = \"thread the wire\"\n\
         [[program.mcode]]\nnumber = 50\naction = \"ignore\"\nmessage = \"no cutter\"\n\
         [[program.mcode]]\nnumber = 82\naction = \"condition\"\ncondition = 2\n\
         [[program.mcode]]\nnumber = 84\naction = \"flush_on\"\n",
        &[],
    )
    .unwrap();
    use crate::gcode::VendorAction;
    let actions: Vec<(u32, VendorAction)> = c
        .program
        .mcodes
        .iter()
        .map(|m| (m.number, m.action.clone()))
        .collect();
    assert_eq!(
        actions,
        vec![
            (60, VendorAction::Pause("thread the wire".into())),
            (50, VendorAction::Ignore("no cutter".into())),
            (82, VendorAction::Condition(2)),
            (84, VendorAction::Flush(true)),
        ]
    );
    assert!(Config::default().program.mcodes.is_empty());
    for (text, gist) in [
        (
            "number = 8\naction = \"flush_on\"",
            "M8 is one of edmd's own M-codes",
        ),
        ("number = 60\naction = \"pause\"", "needs a message"),
        ("number = 60\naction = \"spin\"", "is not one of flush_on"),
        (
            "number = 60\naction = \"condition\"\ncondition = 7",
            "E7 is not a",
        ),
        (
            "number = 60\naction = \"flush_on\"\ncondition = 2",
            "condition is for action",
        ),
        (
            "number = 60\naction = \"ignore\"\nmessage = \"x\"\ncolour = 1",
            "colour",
        ),
    ] {
        let e = load(&format!("[[program.mcode]]\n{text}\n"), &[]).unwrap_err();
        assert!(e.contains(gist), "{text}: {e}");
        assert!(e.starts_with("edmd.toml:"), "{e}");
    }
    let twice = "[[program.mcode]]\nnumber = 60\naction = \"flush_on\"\n".repeat(2);
    assert!(
        load(&twice, &[])
            .unwrap_err()
            .contains("M60 is defined twice")
    );
}

#[test]
fn the_edge_nodes_keys_are_read_and_their_mistakes_located_on_their_line() {
    let c = load(
        "[daemon.mqtt]\nbroker = \"mqtts://broker.plant.lan:8883\"\ngroup_id = \"hall-a\"\n\
         node_id = \"edm-7\"\ncommands = true\n",
        &[],
    )
    .unwrap();
    let m = c.daemon.mqtt.expect("on");
    assert_eq!(m.broker.to_string(), "mqtts://broker.plant.lan:8883");
    assert_eq!(
        (m.group_id.as_str(), m.node_id.as_str()),
        ("hall-a", "edm-7")
    );
    assert!(m.commands);
    assert_eq!(m.keep_alive_s, 10, "the shipped default");
    assert!(
        load("", &[]).unwrap().daemon.mqtt.is_none(),
        "off by default"
    );
    let e = load("[daemon.mqtt]\n\nbroker = \"tcp://x:1\"\n", &[]).unwrap_err();
    assert!(e.starts_with("edmd.toml:3:1: daemon.mqtt.broker:"), "{e}");
    let e = load(
        "[daemon.mqtt]\nbroker = \"mqtt://x:1883\"\ngroup_id = \"a/b\"\n",
        &[],
    )
    .unwrap_err();
    assert!(e.starts_with("edmd.toml:3:1: daemon.mqtt.group_id:"), "{e}");
    let e = load("[daemon.mqtt]\nbrokr = \"mqtt://x:1883\"\n", &[]).unwrap_err();
    assert!(e.starts_with("edmd.toml:2:1: unknown key `brokr`"), "{e}");
    let e = load(
        "[daemon.mqtt]\nbroker = \"mqtt://x:1883\"\nca_file = \"/etc/ca.pem\"\n",
        &[],
    )
    .unwrap_err();
    assert!(
        e.contains("daemon.mqtt.ca_file: is for a TLS broker"),
        "{e}"
    );
    let e = load("", &["daemon.mqtt.keep_alive_s=1"]).unwrap_err();
    assert!(e.contains("--set daemon.mqtt.keep_alive_s=1"), "{e}");
}

#[test]
fn a_files_travel_table_replaces_the_default_whole_for_any_axis() {
    // A sinker's Z limit, written as the shipped file says: the table replaces the default
    // (X and Y) whole, so X and Y have no limit unless the file gives them.
    let text = "[machine]\naxes = [\"X\", \"Y\", \"Z\"]\nstep_mm = [0.001, 0.001, 0.001]\n\
                [machine.travel_mm]\nZ = [-50.0, 10.0]\nX = [0.0, 300.0]\n";
    let c = load(text, &[]).unwrap();
    let z = c.machine.travel[2].expect("Z has its limit");
    assert_eq!((z.min_mm, z.max_mm), (-50.0, 10.0));
    assert_eq!(c.machine.travel[0].map(|t| t.max_mm), Some(300.0));
    assert!(
        c.machine.travel[1].is_none(),
        "Y's default limit is replaced with the table"
    );
    // Entries for axes the machine does not have are not used, as the shipped file says.
    let c = load("[machine.travel_mm]\nU = [-5.0, 5.0]\n", &[]).unwrap();
    assert!(c.machine.travel.iter().all(Option::is_none));
}
