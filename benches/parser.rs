//! G-code parsing throughput on a CAM-style polyline (lines with 3 decimals) and on NURBS blocks.
//! Run: `cargo bench --bench parser`.

use std::fmt::Write as _;
use std::hint::black_box;
use std::io::Cursor;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use edmd::gcode::BlockReader;
use edmd::vocab::Axis;

fn polyline(lines: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0\nF600\n");
    for i in 1..=lines {
        let t = i as f64 * 0.01;
        let _ = writeln!(s, "G1 X{:.3} Y{:.3}", 50.0 * t.cos(), 50.0 * t.sin());
    }
    s.push_str("M30\n");
    s
}

/// `curves` cubic G06.2 curves of four points each, one after the other along X.
fn nurbs_program(curves: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0\nF600\n");
    let mut x = 0.0;
    for _ in 0..curves {
        let _ = writeln!(s, "G06.2 P4 K0 X{x:.3} Y0 R1");
        let _ = writeln!(s, "K0 X{:.3} Y3 R2", x + 1.0);
        let _ = writeln!(s, "K0 X{:.3} Y-3 R1", x + 2.0);
        let _ = writeln!(s, "K0 X{:.3} Y0 R1", x + 3.0);
        s.push_str("K1\nK1\nK1\nK1\n");
        x += 3.0;
    }
    s.push_str("M30\n");
    s
}

fn bench_parse(c: &mut Criterion) {
    let axes = [Axis::X, Axis::Y];
    let programs = [
        ("polyline_20k_lines", polyline(20_000)),
        ("g06_2_2k_curves", nurbs_program(2_000)),
    ];
    let mut group = c.benchmark_group("parse");
    for (name, text) in &programs {
        group.throughput(Throughput::Bytes(text.len() as u64));
        group.bench_function(*name, |b| {
            b.iter(|| {
                let reader =
                    BlockReader::new(Cursor::new(black_box(text.as_bytes())), "b.nc", &axes);
                reader.map(|b| b.unwrap().curve.num_points()).sum::<usize>()
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(20)
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(3));
    targets = bench_parse
}
criterion_main!(benches);
