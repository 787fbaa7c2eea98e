//! motorbench's side of the peer comparison (`benches/peers/compare.sh`):
//! each subcommand does one row's work on the given data, times only that
//! work (the record is read before the clock starts), and prints one JSON
//! line with the time and the answer, which the script checks against the
//! Python peer's.
//!
//! - `dc-fit <record.mcap> <problem.json>`: the output-error optimiser of
//!   the DC model alone from the start values the identification itself
//!   would use, on the problem prepared beforehand (the peer's clock holds
//!   its optimiser alone too); writes that problem (segments, starts,
//!   noise weights, start values) for the peer, which fits the same
//!   residuals from the same start. Also times the whole fit a user calls
//!   (`whole_fit_seconds`: noise estimate, segment starts, intervals and
//!   plot traces besides; no validation refits, no voltage-noise
//!   correction).
//! - `im-fit <problem.json>`: the double-cage Levenberg–Marquardt fit of
//!   three slip sweeps of 50 points from the classical starts; writes the
//!   points and the starts for the peer.
//! - `mcap-write <out.mcap> <samples>`: records `samples` JSON samples (4
//!   channels at 2 kHz) in the contract layout through the recorder.
//! - `mcap-read <record.mcap>`: reads a record and decodes every message.
//! - `record-size <record.mcap>`: prints its segments and samples (for
//!   `benches/diagnosis_cpu.sh`).
//!
//! Built by the script as `cargo build --release --example peers`.

use std::path::Path;
use std::time::Instant;

use motorbench::identify::{output_error, prepare_output_error, OutputErrorOptions, SegmentStart};
use motorbench::record::{read_entries, read_mcap, ChannelSpec, Entry, Recorder, SegmentKind};
use motorbench::record::{TestMeta, SCHEMA_VERSION};
use serde_json::json;

mod im_fit;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |n: usize| -> &str {
        args.get(n).map(String::as_str).unwrap_or_else(|| {
            eprintln!("usage: peers dc-fit|im-fit|mcap-write|mcap-read ARGS (see the source)");
            std::process::exit(2)
        })
    };
    let line = match arg(0) {
        "dc-fit" => dc_fit(Path::new(arg(1)), Path::new(arg(2))),
        "im-fit" => im_fit::run(Path::new(arg(1))),
        "mcap-write" => mcap_write(Path::new(arg(1)), arg(2).parse().expect("a sample count")),
        "mcap-read" => mcap_read(Path::new(arg(1))),
        "record-size" => {
            // Plain text for shell scripts: segments and samples.
            let record = read_mcap(Path::new(arg(1))).expect("a readable record");
            let samples: usize = record.segments.iter().map(|s| s.time.len()).sum();
            println!("{} {samples}", record.segments.len());
            return;
        }
        other => {
            eprintln!("unknown subcommand {other}");
            std::process::exit(2)
        }
    };
    println!("{line}");
}

/// Repetitions of a fit in one process; the fastest is reported (the
/// peers do the same), so neither side's first-call costs (page faults on
/// fresh buffers, cold caches, lazy imports) count.
pub const REPEATS: usize = 3;

/// `f` run [`REPEATS`] times: its last result and the fastest time, s.
pub fn best_of<T>(mut f: impl FnMut() -> T) -> (T, f64) {
    let mut best = f64::INFINITY;
    let mut out = None;
    // PEERS_REPEATS overrides the count, for a profiler's longer run.
    let repeats = std::env::var("PEERS_REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(REPEATS);
    for _ in 0..repeats {
        let clock = Instant::now();
        out = Some(f());
        best = best.min(clock.elapsed().as_secs_f64());
    }
    (out.expect("at least one repetition"), best)
}

fn fit_options() -> OutputErrorOptions {
    OutputErrorOptions {
        validate: false,
        correct_input_noise: false,
        ..OutputErrorOptions::default()
    }
}

fn params_json(p: &motorbench::model::DcParams) -> serde_json::Value {
    json!([p.ra, p.la, p.k, p.j, p.f, p.tst])
}

/// The DC output-error fit alone, timed; the problem written for the peer.
fn dc_fit(record: &Path, problem: &Path) -> serde_json::Value {
    let record = read_mcap(record).expect("a readable record");
    // The start the identification uses (steady-state statics, transient
    // estimates of La and J), taken once, outside the clock.
    let start = output_error(&record, None, &fit_options())
        .expect("an output-error fit")
        .start;
    // The problem the peer is handed (segments, their starts, the noise
    // weights), made outside the clock as the peer's is read outside its
    // own; timed: the optimiser, which is what the peer's clock holds.
    let problem_data = prepare_output_error(&record, Some(start), &fit_options())
        .expect("an output-error problem");
    let ((params, evaluations), seconds) = best_of(|| problem_data.minimise());
    // And the whole fit a user calls, from the same start: the noise
    // estimate, the segment starts, the intervals and the plot traces
    // besides the optimiser (the peer does none of those).
    let (fit, whole_seconds) = best_of(|| {
        output_error(&record, Some(start), &fit_options()).expect("an output-error fit")
    });
    assert_eq!(
        params, fit.params,
        "the optimiser alone ends where the whole fit does"
    );
    let segments: Vec<serde_json::Value> = problem_data
        .segments()
        .iter()
        .map(|(index, how)| {
            let seg = record
                .segments
                .iter()
                .find(|s| s.index == *index)
                .expect("a fitted segment is in the record");
            let start = match how {
                SegmentStart::Settled(u) => json!({"settled": u}),
                SegmentStart::FromRest => json!("rest"),
                SegmentStart::State { current, speed } => json!({"state": [current, speed]}),
            };
            json!({"index": index, "time": seg.time, "voltage": seg.voltage,
                   "current": seg.current, "speed": seg.speed, "start": start})
        })
        .collect();
    let samples: usize = problem_data
        .segments()
        .iter()
        .filter_map(|(i, _)| record.segments.iter().find(|s| s.index == *i))
        .map(|s| s.time.len())
        .sum();
    let noise = problem_data.noise();
    let doc = json!({"start": params_json(&problem_data.start()),
                     "sigma": [noise.current, noise.speed],
                     "segments": segments});
    std::fs::write(problem, doc.to_string()).expect("the problem file is written");
    json!({"seconds": seconds, "whole_fit_seconds": whole_seconds,
           "params": params_json(&params), "evaluations": evaluations,
           "segments": segments.len(), "samples": samples})
}

/// Value of channel `c` at sample `k` (the peer computes the same).
fn sample_value(k: usize, c: usize) -> f64 {
    let t = k as f64 * 5e-4;
    let base = [12.5, 0.75, 104.0, 48.0][c];
    // Three decimals, like a 12-bit ADC reading scaled to units.
    (base * (1.0 + 0.3 * (t * (1.0 + c as f64)).sin()) * 1000.0).round() / 1000.0
}

/// Record `samples` sample messages (4 channels, 2 kHz) through the
/// recorder; the time from start to finish.
fn mcap_write(out: &Path, samples: usize) -> serde_json::Value {
    let _ = std::fs::remove_file(out);
    let meta = TestMeta {
        schema_version: SCHEMA_VERSION.into(),
        kind: SegmentKind::DcStep,
        motor_id: "peer-bench".into(),
        started_at: "2026-12-01T12:00:00Z".into(),
        nameplate: json!({}),
        config: String::new(),
    };
    let channels = [
        ChannelSpec::sensor("armature_voltage", "V", "sim"),
        ChannelSpec::sensor("armature_current", "A", "sim"),
        ChannelSpec::sensor("speed", "rad/s", "sim"),
        ChannelSpec::sensor("winding_temperature", "degC", "sim"),
    ];
    let instants = samples / channels.len();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .build()
        .expect("a runtime");
    let clock = Instant::now();
    let stats = runtime.block_on(async {
        let rec = Recorder::start(out, &meta, &channels, motorbench::record::QUEUE_CAPACITY)
            .expect("the recorder starts");
        for k in 0..instants {
            let values = (0..channels.len())
                .map(|c| (c, sample_value(k, c)))
                .collect();
            rec.send(Entry::Samples {
                t_ns: k as u64 * 500_000,
                values,
            })
            .await
            .expect("the recorder takes the entry");
        }
        rec.finish().await.expect("the recorder finishes")
    });
    let seconds = clock.elapsed().as_secs_f64();
    json!({"seconds": seconds, "messages": stats.messages,
           "samples": instants * channels.len()})
}

/// Read a record and decode every message; a checksum of what was decoded.
fn mcap_read(path: &Path) -> serde_json::Value {
    // Warm the page cache outside the clock, as the peer's first read does.
    let _ = std::fs::read(path).expect("a readable file");
    let clock = Instant::now();
    let (_, _, entries, _) = read_entries(path).expect("a readable record");
    let seconds = clock.elapsed().as_secs_f64();
    let (mut count, mut sum) = (0u64, 0.0f64);
    for e in &entries {
        if let Entry::Samples { values, .. } = e {
            // One by one in file order, as the peer adds them.
            for (_, v) in values {
                count += 1;
                sum += v;
            }
        }
    }
    // The identification's reader too (the same pass plus the record).
    let clock = Instant::now();
    let record = read_mcap(path).expect("a readable record");
    let record_seconds = clock.elapsed().as_secs_f64();
    drop(record);
    json!({"seconds": seconds, "record_seconds": record_seconds,
           "samples": count, "sum": sum})
}
