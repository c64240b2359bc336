//! Runtime benches: Bresenham events alone, the consumer's per-tick core, the loop buffer hand-off under a
//! contending producer (against a lock-free crossbeam queue), `run` end to end in virtual
//! time, and what the I/O adds per tick (parallel port encoding, gap pins, simulated gap).
//!
//! `cargo bench --bench runtime`

use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use crossbeam::queue::ArrayQueue;

use edmd::buffer::{BlockSource, Fetch, LoopBuffer, StepBlock, VecSource};
use edmd::config::Config;
use edmd::fine::{Bresenham, FineSettings, Interpolator};
use edmd::gap::{GapSensor, GapState};
use edmd::output::PulseOutput;
use edmd::parport::{
    Clock, ParportGap, ParportOutput, PinMap, Port, PortWriter, SpinClock, StepTiming,
};
use edmd::servo::Feeds;
use edmd::sim::{SimMachine, SimScript, SimSettings};
use edmd::vocab::MAX_AXES;
use parking_lot::Mutex;

/// Ticks per measured batch.
const TICKS: u64 = 10_000;

/// `edmd run` of `program` with `config`, to its end.
fn run_file(program: &std::path::Path, config: &Config) -> Option<edmd::runtime::JobSummary> {
    let never = std::sync::atomic::AtomicBool::new(false);
    edmd::runtime::run_file(program, config, &never, edmd::runtime::Observers::default()).ok()
}

fn settings(feed: f64) -> FineSettings {
    FineSettings {
        dt: 50e-6,
        accel: 2400.0,
        reverse_accel: 2400.0,
        feeds: Feeds {
            normal: feed,
            open: feed,
            retract: feed,
        },
        shorts: edmd::servo::ShortRules::IMMEDIATE,
        step_mm: [0.001; MAX_AXES],
        max_short_ticks: 0,
        law: edmd::servo::Law::ThreeState,
        excursions: edmd::fine::ExcursionSettings::OFF,
        dry_run: false,
        breakthrough: edmd::fine::BreakthroughSettings::OFF,
        jerk: 0.0,
        lift_axis: None,
    }
}

/// Blocks of `len` steps along a direction using `axes` axes.
fn blocks(count: u64, len: i64, axes: usize) -> Vec<StepBlock> {
    let mut at = [0i64; MAX_AXES];
    (0..count)
        .map(|seq| {
            let mut end = at;
            for (i, e) in end.iter_mut().enumerate().take(axes) {
                *e += len * [7, -5, 3, 2, -1, 4][i] / 7;
            }
            let b = StepBlock {
                seq,
                start: at,
                end,
                length_mm: len as f64 * 0.001,
                v_entry: 1e3,
                v_exit: 1e3,
                v_cruise: 1e3,
                v_limit: 1e3,
                path: edmd::preprocess::PathLimits {
                    cruise: 1e3,
                    entry: 1e3,
                    exit: 1e3,
                },
                line: 1,
                ..StepBlock::EMPTY
            };
            at = end;
            b
        })
        .collect()
}

/// A tick core warmed up to cruising speed on long blocks.
fn cruising(feed: f64, axes: usize, block_len: i64) -> (Interpolator, VecSource) {
    let mut source = VecSource::new(blocks(1000, block_len, axes), 256);
    let mut fine = Interpolator::new(settings(feed), [0; MAX_AXES]);
    for _ in 0..2000 {
        fine.tick(GapState::Normal, &mut source);
    }
    (fine, source)
}

/// Bresenham alone: events per second walking one long block, forward (cutting) and backward
/// (turn-back), against recomputing each event's offset from the closed form (what a walk
/// without the incremental error terms would cost).
fn bresenham(c: &mut Criterion) {
    const EVENTS: i64 = 100_000;
    let mut group = c.benchmark_group("bresenham");
    group.throughput(Throughput::Elements(EVENTS as u64));
    for axes in [2usize, 3, 6] {
        let mut delta = [0i64; MAX_AXES];
        for (i, d) in delta.iter_mut().enumerate().take(axes) {
            *d = EVENTS * [7, -5, 3, 2, -1, 4][i] / 7;
        }
        group.bench_function(format!("forward, {axes} axes"), |b| {
            b.iter(|| {
                let mut walk = Bresenham::new(black_box(&delta), false);
                let mut steps = [0i8; MAX_AXES];
                let mut position = [0i64; MAX_AXES];
                while !walk.at_end() {
                    walk.forward(&mut steps);
                    for (p, &s) in position.iter_mut().zip(&steps) {
                        *p += s as i64;
                    }
                }
                position
            })
        });
        group.bench_function(format!("backward, {axes} axes"), |b| {
            b.iter(|| {
                let mut walk = Bresenham::new(black_box(&delta), true);
                let mut steps = [0i8; MAX_AXES];
                let mut position = delta;
                while !walk.at_start() {
                    walk.backward(&mut steps);
                    for (p, &s) in position.iter_mut().zip(&steps) {
                        *p += s as i64;
                    }
                }
                position
            })
        });
        group.bench_function(format!("closed form per event, {axes} axes"), |b| {
            b.iter(|| {
                let mut last = [0i64; MAX_AXES];
                for k in 1..=EVENTS {
                    last = Bresenham::offset_at(black_box(&delta), k);
                }
                last
            })
        });
    }
    group.finish();
}

fn tick_core(c: &mut Criterion) {
    let mut group = c.benchmark_group("tick");
    group.throughput(Throughput::Elements(TICKS));
    // 20 mm/s at 1 µm steps and 50 µs: one event (a step on every axis that moves) per tick.
    for (name, feed, axes, len) in [
        ("stepping 2 axes", 20.0, 2, 100_000),
        ("stepping 6 axes", 20.0, 6, 100_000),
        ("stepping, 20-step blocks", 20.0, 3, 20),
        ("idle between steps (1 mm/s)", 1.0, 2, 100_000),
    ] {
        group.bench_function(name, |b| {
            b.iter_batched_ref(
                || cruising(feed, axes, len),
                |(fine, source)| {
                    for _ in 0..TICKS {
                        black_box(fine.tick(GapState::Normal, source));
                    }
                },
                BatchSize::LargeInput,
            )
        });
    }
    // Turning back over short blocks: the reserved area walked backwards.
    group.bench_function("turning back, 20-step blocks", |b| {
        b.iter_batched_ref(
            || {
                let (mut fine, mut source) = cruising(20.0, 3, 20);
                for _ in 0..10 {
                    fine.tick(GapState::Short, &mut source);
                }
                (fine, source)
            },
            |(fine, source)| {
                for _ in 0..TICKS {
                    black_box(fine.tick(GapState::Short, source));
                }
            },
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

/// Blocks handed from a producer thread to a consumer thread.
const HANDOFF: u64 = 100_000;

fn buffer_handoff(c: &mut Criterion) {
    let mut group = c.benchmark_group("buffer hand-off");
    group.throughput(Throughput::Elements(HANDOFF));
    group.sample_size(20);
    group.bench_function(
        "LoopBuffer (parking_lot Mutex + Condvar), 1024 slots",
        |b| {
            b.iter(|| {
                let buffer = LoopBuffer::new(1024, 256);
                std::thread::scope(|s| {
                    s.spawn(|| {
                        for seq in 0..HANDOFF {
                            buffer
                                .push(&StepBlock {
                                    seq,
                                    ..StepBlock::EMPTY
                                })
                                .unwrap();
                        }
                        buffer.close();
                    });
                    let mut consumer = buffer.consumer(true);
                    let mut out = StepBlock::EMPTY;
                    let mut n = 0;
                    while consumer.next(&mut out) == Fetch::Block {
                        n += 1;
                    }
                    assert_eq!(n, HANDOFF);
                });
            })
        },
    );
    // (Blocks are built from `StepBlock::EMPTY` inside the closures: capturing a local
    // `StepBlock` in these nested closures trips an internal compiler error in rustc 1.95.)
    // The alternative: a lock-free bounded queue for the data (the producer spins with a
    // yield when full, the consumer when empty). It hands each block over once, so turn-back
    // would need a second, consumer-side ring for the reserved area.
    group.bench_function("crossbeam ArrayQueue (lock-free), 1024 slots", |b| {
        b.iter(|| {
            let queue = ArrayQueue::new(1024);
            std::thread::scope(|s| {
                s.spawn(|| {
                    for seq in 0..HANDOFF {
                        let mut item = StepBlock {
                            seq,
                            ..StepBlock::EMPTY
                        };
                        while let Err(back) = queue.push(item) {
                            item = back;
                            std::thread::yield_now();
                        }
                    }
                });
                let mut n = 0;
                while n < HANDOFF {
                    match queue.pop() {
                        Some(b) => {
                            black_box(b);
                            n += 1
                        }
                        None => std::thread::yield_now(),
                    }
                }
            });
        })
    });
    // The consumer's cost per block when the buffer is full and the producer waits: one lock,
    // one copy, one notify.
    group.bench_function("consumer next() on a full buffer, uncontended", |b| {
        b.iter_batched_ref(
            || {
                let buffer = LoopBuffer::new(HANDOFF as usize + 1, 256);
                for seq in 0..HANDOFF {
                    buffer.try_push(&StepBlock {
                        seq,
                        ..StepBlock::EMPTY
                    });
                }
                buffer
            },
            |buffer| {
                let mut consumer = buffer.consumer(false);
                let mut out = StepBlock::EMPTY;
                while consumer.next(&mut out) == Fetch::Block {}
            },
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

fn end_to_end(c: &mut Criterion) {
    let program = Path::new(env!("CARGO_MANIFEST_DIR")).join("../programs/jin-table1-g06_2.nc");
    let mut group = c.benchmark_group("run, virtual time");
    group.sample_size(10);
    for (name, feed) in [
        ("at the step cap (1200 mm/min)", 1200.0),
        ("EDM feed (60 mm/min)", 60.0),
    ] {
        let overrides: Vec<String> = [
            "output.kind=null".to_string(),
            "gap.kind=none".to_string(),
            format!("servo.normal_feed_mm_per_min={feed}"),
        ]
        .into();
        let config = Config::load(None, &overrides).unwrap();
        let summary = run_file(&program, &config).unwrap();
        let steps: u64 = summary.steps_per_axis.iter().sum();
        group.throughput(Throughput::Elements(steps));
        group.bench_function(format!("jin-table1-g06_2.nc, steps, {name}"), |b| {
            b.iter(|| black_box(run_file(&program, &config).unwrap()))
        });
    }
    group.finish();
}

/// A port that takes every write and reads a quiet gap.
struct NoopPort;

impl Port for NoopPort {
    fn write_data(&mut self, value: u8) -> std::io::Result<()> {
        std::hint::black_box(value);
        Ok(())
    }
    fn write_control(&mut self, value: u8) -> std::io::Result<()> {
        std::hint::black_box(value);
        Ok(())
    }
    fn read_status(&mut self) -> std::io::Result<u8> {
        Ok(0b1000_0111)
    }
}

/// A clock that never waits: the encoding's own CPU cost, without the step timing.
struct NoWait;

impl Clock for NoWait {
    fn now_ns(&mut self) -> u64 {
        0
    }
    fn wait_until_ns(&mut self, _: u64) {}
}

/// The cost the I/O adds to a tick: the port's encoding and register writes, the gap pins,
/// the simulated gap.
fn io_per_tick(c: &mut Criterion) {
    let mut group = c.benchmark_group("io per tick");
    let config = Config::default();
    let map = PinMap::from_config(&config);
    let timing = StepTiming::from_config(&config);
    let port = Arc::new(Mutex::new(PortWriter::new(NoopPort, map.idle())));
    let mut output =
        ParportOutput::new(port.clone(), map.clone(), timing, NoWait, "bench").unwrap();
    let steps = [[1, 1, 0, 0, 0, 0], [-1, 1, 0, 0, 0, 0]];
    let mut k = 0u64;
    group.bench_function("parport write, 2 axes stepping, X reversing", |b| {
        b.iter(|| {
            k += 1;
            output
                .write(k, &steps[(k & 1) as usize], GapState::Normal)
                .unwrap();
        })
    });
    group.bench_function("parport write, no step", |b| {
        b.iter(|| output.write(k, &[0; 6], GapState::Normal).unwrap())
    });
    // The real clock: the deliberate in-tick waits (dir_setup + step_length = 25 µs with
    // stepconf's timing) plus the spinning's overshoot.
    let spin_port = Arc::new(Mutex::new(PortWriter::new(NoopPort, map.idle())));
    let mut spinning =
        ParportOutput::new(spin_port, map.clone(), timing, SpinClock, "bench").unwrap();
    group.bench_function("parport write, spin clock, stepconf timing", |b| {
        b.iter(|| {
            k += 1;
            spinning
                .write(k, &steps[(k & 1) as usize], GapState::Normal)
                .unwrap();
        })
    });
    let mut gap = ParportGap::new(port, map, 3, "bench");
    group.bench_function("parport gap sample (status read, filter 3)", |b| {
        b.iter(|| gap.sample(k).unwrap())
    });
    let mut sim = SimMachine::new(
        &SimSettings::from_config(&config),
        &[(0.0, 1e9)],
        SimScript::default(),
    )
    .gap;
    let x = [1, 0, 0, 0, 0, 0];
    group.bench_function("sim gap sample + observe", |b| {
        b.iter(|| {
            let state = sim.sample(k).unwrap();
            sim.observe(&x, 1);
            state
        })
    });
    // The discharge model's tick at a sparking gap (8 µm, the shipped E21), and the
    // adaptive law's share of a tick: what issue [3/7] adds to the 50 µs.
    let edmd::sim::SimModel::Discharge(params) = &config.sim.model else {
        panic!("the shipped sim.model is the discharge model");
    };
    let mut model = edmd::sim::Discharges::new(**params);
    let e21 = edmd::vocab::GeneratorSetPoints {
        on_time_us: 8.0,
        off_time_us: 10.0,
        peak_current_a: 12.0,
        open_voltage_v: 90.0,
        wire_speed_m_per_min: 9.0,
        ..Default::default()
    };
    let mut rng = edmd::rng::SplitMix64::new(1);
    group.bench_function("discharge model tick (8 µm gap, E21)", |b| {
        b.iter(|| model.tick(50.0, 8.0, &e21, &mut rng))
    });
    let mut adapted = config.clone();
    adapted.adaptive.enabled = true;
    let mut process =
        edmd::process::Process::new(edmd::process::ConditionTable::from_config(&adapted));
    process.enter(4);
    let pulses = edmd::vocab::PulseCounts {
        normal: 2,
        arc: 0,
        short: 0,
        open: 0,
        delay_sum_us: 30.0,
    };
    group.bench_function("adaptive law per tick (window of 20)", |b| {
        b.iter(|| process.observe(Some(&pulses), 1e-5, Some(1.0)))
    });
    group.finish();
}

criterion_group!(
    benches,
    bresenham,
    tick_core,
    buffer_handoff,
    end_to_end,
    io_per_tick
);
criterion_main!(benches);
