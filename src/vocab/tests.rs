use super::*;

#[test]
fn numbers_in_messages_read_as_written() {
    let shown = |v: f64| Num(v).to_string();
    assert_eq!(shown(0.10000000000000178), "0.1");
    assert_eq!(shown(0.15), "0.15");
    assert_eq!(shown(-5.0), "-5");
    assert_eq!(shown(1e200), "1e200");
    assert_eq!(shown(1.5e-9), "1.5e-9");
    assert_eq!(shown(123456.7891234), "123456.789123");
    assert_eq!(shown(-0.0000001), "-1e-7");
    assert_eq!(shown(-0.0), "0");
    assert_eq!(shown(1e9), "1e9");
    assert_eq!(shown(f64::INFINITY), "inf");
}

#[test]
fn axis_letters_round_trip() {
    for axis in Axis::ALL {
        assert_eq!(Axis::from_letter(axis.letter()), Some(axis));
    }
    assert_eq!(Axis::from_letter('W'), None);
}

#[test]
fn gap_state_names_round_trip() {
    for state in [GapState::Normal, GapState::Open, GapState::Short] {
        assert_eq!(GapState::from_name(state.name()), Some(state));
    }
    assert_eq!(GapState::from_name("SHORT"), Some(GapState::Short));
    assert_eq!(GapState::from_name("shorted"), None);
}

#[test]
fn a_leading_bom_is_skipped_and_only_there() {
    assert_eq!(without_bom("\u{feff}G1 X1"), "G1 X1");
    assert_eq!(without_bom("G1 X1"), "G1 X1");
    assert_eq!(without_bom("G1\u{feff}"), "G1\u{feff}");
}

#[test]
fn tick_period_bounds_and_conversions() {
    assert_eq!(TickPeriod::from_us(0), None);
    assert_eq!(TickPeriod::from_us(1_000_001), None);
    let t = TickPeriod::from_us(50).unwrap();
    assert_eq!(t.us(), 50);
    assert_eq!(t.ns(), 50_000);
    // The exact expression every caller used before this type existed.
    let tick_us: u32 = 50;
    assert_eq!(t.secs().to_bits(), (tick_us as f64 * 1e-6).to_bits());
    assert_eq!(t.ticks_to_secs(20_000), 20_000.0 * (50.0 * 1e-6));
    assert_eq!(t.to_string(), "50 µs");
    let max = TickPeriod::from_us(TickPeriod::MAX_US).unwrap();
    assert_eq!(max.ns(), 1_000_000_000);
}

/// Every switch of every axis has its own bit; a step is blocked only by the switch it
/// runs further into, never by one it moves away from or one of another axis.
#[test]
fn a_limit_set_blocks_only_motion_into_a_closed_switch() {
    let mut set = LimitSet::EMPTY;
    for axis in Axis::ALL {
        for positive in [false, true] {
            let s = LimitSwitch { axis, positive };
            assert!(!set.contains(s));
            set.insert(s);
            assert!(set.contains(s));
        }
    }
    assert_eq!(set.iter().count(), 16);
    let mut set = LimitSet::EMPTY;
    let x_plus = LimitSwitch::parse("X+").unwrap();
    set.insert(x_plus);
    assert_eq!(set.to_string(), "X+");
    // A machine X, U (U in slot 1).
    let mut axes = [None; MAX_AXES];
    axes[0] = Some(Axis::X);
    axes[1] = Some(Axis::U);
    let steps = |x: i8, u: i8| {
        let mut s = [0; MAX_AXES];
        s[0] = x;
        s[1] = u;
        s
    };
    assert_eq!(set.blocking(&axes, &steps(1, 0)), Some(x_plus));
    assert_eq!(set.blocking(&axes, &steps(1, -1)), Some(x_plus));
    assert_eq!(set.blocking(&axes, &steps(-1, 0)), None, "away");
    assert_eq!(set.blocking(&axes, &steps(0, 1)), None, "another axis");
    assert_eq!(set.blocking(&axes, &steps(0, 0)), None);
    set.remove(x_plus);
    assert!(set.is_empty());
    let u_minus = LimitSwitch::parse("u-").unwrap();
    set.insert(u_minus);
    assert_eq!(set.blocking(&axes, &steps(1, -1)), Some(u_minus));
    let inputs = SafetyInputs {
        estop: false,
        limits: set,
    };
    assert_eq!(Trip::of(inputs), Some(Trip::Limit(u_minus)));
    let both = inputs.merged(SafetyInputs {
        estop: true,
        limits: LimitSet::EMPTY,
    });
    assert_eq!(Trip::of(both), Some(Trip::EStop));
    assert!(both.limits.contains(u_minus));
    for trip in [Trip::EStop, Trip::Limit(u_minus)] {
        assert_eq!(Trip::parse(&trip.name()), Some(trip));
    }
    assert_eq!(Trip::parse("limit"), None);
}
