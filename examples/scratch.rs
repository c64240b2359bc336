use edmd::config::{Config, Predictor, Segmentation};
use edmd::gcode::open_program;
use edmd::preprocess::*;
use std::sync::Arc;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mut cfg = Config::default();
    if args.len() > 2 && args[2] == "period" {
        cfg.interpolation.segmentation = Segmentation::Period;
    }
    if args.len() > 3 && args[3] == "hamming" {
        cfg.interpolation.predictor = Predictor::Hamming;
    }
    if args.len() > 4 {
        cfg.interpolation.max_corrections = args[4].parse().unwrap();
    }
    cfg.interpolation.max_segment_mm = 1000.0;
    let settings = PlanSettings::from_config(&cfg);
    let reader = open_program(std::path::Path::new(&args[1]), &cfg.machine.axes).unwrap();
    let blocks: Vec<Arc<edmd::gcode::Block>> = reader.map(|b| Arc::new(b.unwrap())).collect();
    let reps: usize = std::env::var("REPEAT")
        .ok()
        .map(|v| v.parse().unwrap())
        .unwrap_or(0);
    let tr = std::time::Instant::now();
    let mut n = 0u64;
    for _ in 0..reps {
        let mut seg = Segmenter::new(settings.clone());
        for b in &blocks {
            seg.segment_block(b, |_s| n += 1);
        }
    }
    if reps > 0 {
        println!(
            "segmenter only: {:.0} segs/s",
            n as f64 / tr.elapsed().as_secs_f64()
        );
    }
    let t0 = std::time::Instant::now();
    let mut pre = Preprocessor::new(settings.clone());
    let mut segs = vec![];
    for b in &blocks {
        pre.push_block(b.clone(), |s| segs.push(s));
    }
    pre.finish(|s| segs.push(s));
    let el = t0.elapsed();
    let st = pre.stats();
    let time: f64 = segs.iter().map(|s| s.duration).sum();
    let maxerr = segs.iter().map(|s| s.chord_error).fold(0.0, f64::max);
    let fl: Vec<f64> = segs.iter().filter_map(|s| s.fluctuation).collect();
    let maxfl = fl.iter().cloned().fold(0.0, f64::max);
    let meanfl = fl.iter().sum::<f64>() / fl.len().max(1) as f64;
    let maxv = segs.iter().map(|s| s.v_exit).fold(0.0, f64::max);
    let mut maxat: f64 = 0.0;
    let mut maxan: f64 = 0.0;
    for w in segs.windows(2) {
        if w[0].duration > 0.0
            && w[1].duration > 0.0
            && w[0].fluctuation.is_some()
            && w[1].fluctuation.is_some()
        {
            let a = (w[1].v_exit - w[0].v_exit) / (0.5 * (w[0].duration + w[1].duration));
            maxat = maxat.max(a.abs());
        }
    }
    for s in &segs {
        maxan = maxan.max(s.v_exit * s.v_exit / s.rho_end);
    }
    println!("{:?}", st);
    println!(
        "segments {} time {:.4} s maxerr {:.6} maxfl {:.3e} meanfl {:.3e} maxv {:.2} max_aT(step) {:.1} max_aN {:.1} evals/seg {:.3} ({:?})",
        segs.len(),
        time,
        maxerr,
        maxfl,
        meanfl,
        maxv,
        maxat,
        maxan,
        (st.segmenter.evals + st.step_evals) as f64 / segs.len() as f64,
        el
    );
    let refs: Vec<&edmd::gcode::Block> = blocks.iter().map(|b| b.as_ref()).collect();
    let t1 = std::time::Instant::now();
    println!(
        "bound {:.4} s ({:?})",
        bound::time_optimal_bound(&refs, &settings, 0.005),
        t1.elapsed()
    );
}
#[allow(dead_code)]
fn unused() {}
