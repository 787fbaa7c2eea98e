//! Physical plausibility of a DC record's channel values, checked before
//! any method runs: a reading no real motor or rig produces (1e308 A, a
//! voltage above any real supply, a current that never changes sign while
//! the voltage does) is a wrong file, column or unit, and the user needs
//! to hear that, not that no method applies.
//!
//! The bounds are far beyond any DC machine, so they never refuse a real
//! record: 20 kV (traction supplies are at most 3 kV), 100 kA (the largest
//! mill motors draw some 10 kA), 2·10⁵ rad/s (1.9 million r/min; the
//! fastest electrical machines turn at some 500 000 r/min).

use std::path::PathBuf;

use crate::record::{data_lines, read_dc_csv, ColumnMap, DcSegment, Record, SegmentKind};

/// Largest armature voltage magnitude accepted, V.
pub const MAX_VOLTAGE: f64 = 2e4;
/// Largest armature current magnitude accepted, A.
pub const MAX_CURRENT: f64 = 1e5;
/// Largest speed magnitude accepted, rad/s.
pub const MAX_SPEED: f64 = 2e5;

/// Voltage fraction of its largest magnitude that counts as a reversal.
const REVERSAL: f64 = 0.2;
/// Share of samples the voltage must spend at each sign to count as
/// reversing.
const REVERSAL_SHARE: f64 = 0.05;
/// Largest margin about zero, as a share of the current's peak, within
/// which a current of the other sign counts as noise.
const MAX_MARGIN: f64 = 0.1;

/// A channel whose values no real DC motor produces.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("segment {segment} ({label}), column {column}: {reason}")]
pub struct ImplausibleInput {
    /// Segment index.
    pub segment: u32,
    /// Segment label.
    pub label: String,
    /// The contract's column name, e.g. `armature_current_A`.
    pub column: &'static str,
    /// What is wrong, with the value.
    pub reason: String,
    /// The sample (from 0, within the segment) that shows it, where one
    /// does.
    pub sample: Option<u32>,
}

/// An [`ImplausibleInput`] in a record loaded from files, with the file
/// that holds the segment when one does, and the line of the sample in a
/// CSV file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}{input}", file_prefix(.file.as_deref(), *.line))]
pub struct ImplausibleFile {
    /// The file that holds the segment; `None` for a record-wide finding
    /// in several files.
    pub file: Option<PathBuf>,
    /// The line (from 1) of the sample that shows it, in a CSV file.
    pub line: Option<u32>,
    /// What is implausible.
    #[source]
    pub input: ImplausibleInput,
}

/// `<file>:<line>: `, `<file>: `, or nothing without a file.
fn file_prefix(file: Option<&std::path::Path>, line: Option<u32>) -> String {
    match (file, line) {
        (Some(f), Some(line)) => format!("{}:{line}: ", f.display()),
        (Some(f), None) => format!("{}: ", f.display()),
        (None, _) => String::new(),
    }
}

/// Check every segment's channels, then the record as a whole.
pub fn check_plausible(record: &Record) -> Result<(), ImplausibleInput> {
    for seg in &record.segments {
        check_segment(seg)?;
    }
    check_current_reverses(record)?;
    check_power_flows_in(record)?;
    check_speed_glitches(record)
}

/// [`check_plausible`] on a record loaded from `files`, the error naming
/// the file that holds the segment (or every file, for a record-wide
/// finding), as the command line reports it.
pub fn check_plausible_files(
    record: &Record,
    kind: SegmentKind,
    files: &[PathBuf],
    columns: &ColumnMap,
) -> Result<(), ImplausibleFile> {
    let Err(e) = check_plausible(record) else {
        return Ok(());
    };
    // Each file read with the index the whole record gave it (its
    // position, unless it declares one).
    let holder = files.iter().enumerate().find(|(n, f)| {
        files.len() == 1
            || read_dc_csv(f, kind, *n as u32, columns).is_ok_and(|s| s.index == e.segment)
    });
    // The sample's line, in a CSV file (an MCAP record has none).
    let line = holder
        .filter(|(_, f)| {
            !f.extension()
                .is_some_and(|x| x.eq_ignore_ascii_case("mcap"))
        })
        .zip(e.sample)
        .and_then(|((_, f), k)| data_lines(f).ok()?.get(k as usize).copied())
        .and_then(|line| u32::try_from(line).ok());
    Err(ImplausibleFile {
        file: holder.map(|(_, f)| f.clone()),
        line,
        input: e,
    })
}

fn check_segment(seg: &DcSegment) -> Result<(), ImplausibleInput> {
    for (column, values, limit, unit) in [
        ("armature_voltage_V", &seg.voltage, MAX_VOLTAGE, "V"),
        ("armature_current_A", &seg.current, MAX_CURRENT, "A"),
        ("speed_rad_s", &seg.speed, MAX_SPEED, "rad/s"),
    ] {
        let bad = values
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && v.abs() <= limit));
        if let Some((k, v)) = bad {
            let reason = if v.is_finite() {
                format!(
                    "sample {k} reads {v:e} {unit}, beyond any real DC motor (|value| ≤ {limit:e} {unit}); \
                     check the column order and the unit"
                )
            } else {
                format!("sample {k} is {v}, not a number")
            };
            return Err(ImplausibleInput {
                segment: seg.index,
                label: seg.label.clone(),
                column,
                reason,
                sample: u32::try_from(k).ok(),
            });
        }
    }
    Ok(())
}

/// The armature current must take the voltage's sign somewhere when the
/// voltage reverses for a while: a motor's current follows a reversed
/// supply. One that never does is read as a magnitude (a rectified or
/// unsigned sensor) or belongs to another channel.
fn check_current_reverses(record: &Record) -> Result<(), ImplausibleInput> {
    let u_peak = record
        .segments
        .iter()
        .flat_map(|s| s.voltage.iter())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let n: usize = record.segments.iter().map(|s| s.voltage.len()).sum();
    if n == 0 || u_peak == 0.0 {
        return Ok(());
    }
    let share = |pred: &dyn Fn(f64) -> bool| {
        record
            .segments
            .iter()
            .flat_map(|s| s.voltage.iter())
            .filter(|v| pred(**v))
            .count() as f64
            / n as f64
    };
    let pos = share(&|v| v > REVERSAL * u_peak);
    let neg = share(&|v| v < -REVERSAL * u_peak);
    if pos < REVERSAL_SHARE || neg < REVERSAL_SHARE {
        return Ok(());
    }
    let i_peak = record
        .segments
        .iter()
        .flat_map(|s| s.current.iter())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let noise = record
        .segments
        .iter()
        .map(|s| super::levels::white_noise(&s.current))
        .fold(0.0f64, f64::max);
    // The noise estimate (second differences) reads a current that moves
    // from sample to sample as noise: a closed loop's or a coarsely
    // sampled record's. A margin that large would call any reversal noise,
    // so it stops at a tenth of the peak; a rectified reading's noise
    // below zero stays within that.
    let margin = (3.0 * noise).max(1e-3 * i_peak).min(MAX_MARGIN * i_peak);
    let (lo, hi) = record
        .segments
        .iter()
        .flat_map(|s| s.current.iter())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    if lo < -margin && hi > margin {
        return Ok(());
    }
    let seg = record
        .segments
        .iter()
        .find(|s| !s.current.is_empty())
        .unwrap_or(&record.segments[0]);
    Err(ImplausibleInput {
        segment: seg.index,
        label: seg.label.clone(),
        column: "armature_current_A",
        reason: format!(
            "the current never changes sign ({lo:.4} … {hi:.4} A over the record) while the voltage \
             reverses ({:.0} % of the samples above +{:.3} V, {:.0} % below −{:.3} V): a motor's current \
             follows a reversed supply; is the current read as a magnitude (an unsigned or rectified \
             sensor), or is this another channel?",
            100.0 * pos,
            REVERSAL * u_peak,
            100.0 * neg,
            REVERSAL * u_peak
        ),
        sample: None,
    })
}

/// Share of the record's speed range (its 2nd to 98th percentile) by
/// which a glitch leaves both its neighbours and the range itself.
const GLITCH_JUMP: f64 = 0.5;
/// Share of the speed range within which a glitch's neighbours agree.
const GLITCH_NEIGHBOURS: f64 = 0.1;
/// The speed range leaves out this fraction's inverse of the readings at
/// each end (2 %), so that glitches do not widen it.
const GLITCH_TRIM: usize = 50;
/// Times the median sample-to-sample change a glitch also leaves both
/// neighbours by: noise about a steady speed never does.
const GLITCH_STEPS: f64 = 10.0;

/// A speed reading that leaves the record's range and both its neighbours
/// by half that range, while the neighbours agree with each other, is a
/// glitch: a shaft cannot leave its speed and come back within one
/// sample. An encoder counter's wrap or a corrupted frame does, and three
/// such readings per segment turn every fit (`K` of a blind case 1.31 →
/// 0.12). The range leaves out the extreme 2 % of readings at each end,
/// so the glitches themselves do not widen it; the reading must lie
/// outside it by half of it, and leave its neighbours by ten times the
/// median change between samples, so noise about a steady speed never
/// counts.
fn check_speed_glitches(record: &Record) -> Result<(), ImplausibleInput> {
    let mut sorted: Vec<f64> = record
        .segments
        .iter()
        .flat_map(|s| s.speed.iter().copied())
        .collect();
    if sorted.len() < 3 {
        return Ok(());
    }
    sorted.sort_by(f64::total_cmp);
    let cut = sorted.len() / GLITCH_TRIM;
    let (lo, hi) = (sorted[cut], sorted[sorted.len() - 1 - cut]);
    // Finite readings (the range checks ran first): range is ≥ 0.
    let range = hi - lo;
    if range <= 0.0 {
        return Ok(());
    }
    let mut steps: Vec<f64> = record
        .segments
        .iter()
        .flat_map(|s| s.speed.windows(2).map(|w| (w[1] - w[0]).abs()))
        .collect();
    let typical = if steps.is_empty() {
        0.0
    } else {
        let mid = steps.len() / 2;
        *steps.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    let jump = (GLITCH_JUMP * range).max(GLITCH_STEPS * typical);
    for seg in &record.segments {
        for (k, w) in seg.speed.windows(3).enumerate() {
            let (a, b, c) = (w[0], w[1], w[2]);
            if (b - a).abs() > jump
                && (b - c).abs() > jump
                && (a - c).abs() < GLITCH_NEIGHBOURS * range
                && (b > hi + jump || b < lo - jump)
            {
                return Err(ImplausibleInput {
                    segment: seg.index,
                    label: seg.label.clone(),
                    column: "speed_rad_s",
                    reason: format!(
                        "sample {} reads {b} rad/s between {a} and {c}, outside the record's \
                         range ({lo:.4} … {hi:.4} rad/s): a shaft cannot leave its speed and \
                         return within one sample, so this is a glitch of the speed reading \
                         (an encoder counter's wrap, a corrupted frame); correct or remove \
                         that row",
                        k + 1
                    ),
                    sample: u32::try_from(k + 1).ok(),
                });
            }
        }
    }
    Ok(())
}

/// One channel of a segment.
type ChannelOf = fn(&DcSegment) -> &[f64];

fn current_of(s: &DcSegment) -> &[f64] {
    &s.current
}

fn speed_of(s: &DcSegment) -> &[f64] {
    &s.speed
}

/// Share of `Σ|x·y|` by which `Σ x·y` must be negative for a channel to
/// count as reversed: three quarters of the product's magnitude against
/// the voltage. Braking within a record (a controller reversing, a step
/// down) takes a small share.
const AGAINST: f64 = 0.5;

/// A motor driven by its armature takes electrical power in on balance
/// (`Σ U·i > 0`: the losses, plus the kinetic energy it gains) and turns
/// the way its voltage drives it (`Σ U·ω > 0`: the back-EMF opposes the
/// supply). A record that is mostly the other way round has a channel of
/// reversed polarity: a current sensor mounted the other way round, an
/// encoder counting backwards.
fn check_power_flows_in(record: &Record) -> Result<(), ImplausibleInput> {
    let driven: Vec<&DcSegment> = record
        .segments
        .iter()
        .filter(|s| s.kind != Some(SegmentKind::DcCoastdown) && !super::is_coastdown(s))
        .collect();
    let balance = |y: ChannelOf| {
        driven
            .iter()
            .flat_map(|s| s.voltage.iter().zip(y(s)))
            .fold((0.0, 0.0), |(net, gross), (u, v)| {
                (net + u * v, gross + (u * v).abs())
            })
    };
    let checks: [(&'static str, &str, ChannelOf, &str); 2] = [
        (
            "armature_current_A",
            "i",
            current_of,
            "the electrical input power U·i is negative on balance: a motor driven by its \
             armature takes power in; is the current sensor's polarity reversed (negate the column)?",
        ),
        (
            "speed_rad_s",
            "ω",
            speed_of,
            "the speed turns against the armature voltage on balance: a motor turns the way \
             its voltage drives it; does the encoder or tachometer count the other way (negate \
             the column)?",
        ),
    ];
    for (column, symbol, y, why) in checks {
        let (net, gross) = balance(y);
        if gross > 0.0 && net < -AGAINST * gross {
            let seg = driven[0];
            return Err(ImplausibleInput {
                segment: seg.index,
                label: seg.label.clone(),
                column,
                reason: format!(
                    "{why} (Σ U·{symbol} is {:.0} % of Σ |U·{symbol}| over the driven segments)",
                    100.0 * net / gross,
                ),
                sample: None,
            });
        }
    }
    Ok(())
}

/// Fewest consecutive readings at a channel's extreme that make a flat
/// top.
const FLAT_TOP: usize = 3;
/// How many times longer than any other run of equal readings in the
/// channel a flat top must be: a sensor below its resolution repeats its
/// readings at every settled level alike, while a clipping one repeats
/// only its full scale.
const LONGER: usize = 2;

/// Warnings for channels that clip: current or speed repeating exactly its
/// largest magnitude for longer than it repeats any other reading (an ADC
/// at full scale, a sensor at the end of its range). The fits take those
/// readings as true, so the estimates are biased; the user needs to hear
/// it.
pub fn clipped_channels(record: &Record) -> Vec<String> {
    let mut out = Vec::new();
    let channels: [(&str, &str, ChannelOf); 2] = [
        ("armature_current_A", "A", current_of),
        ("speed_rad_s", "rad/s", speed_of),
    ];
    for (column, unit, y) in channels {
        let peak = record
            .segments
            .iter()
            .flat_map(|s| y(s).iter())
            .fold(0.0f64, |m, v| m.max(v.abs()));
        if peak == 0.0 {
            continue;
        }
        // Longest run of equal readings at the extreme, and elsewhere.
        let (mut top, mut other, mut at) = (0usize, 0usize, Vec::new());
        for s in &record.segments {
            for run in y(s).chunk_by(|a, b| a == b) {
                if run[0].abs() == peak {
                    top = top.max(run.len());
                    at.push(s.index);
                } else {
                    other = other.max(run.len());
                }
            }
        }
        if top >= FLAT_TOP && other > 0 && top > LONGER * other {
            at.dedup();
            let at: Vec<String> = at.iter().map(u32::to_string).collect();
            out.push(format!(
                "column {column} repeats its largest magnitude, {peak} {unit}, for up to {top} \
                 readings in a row (no other reading repeats more than {other} times; segment {}): \
                 the sensor or its ADC clips there, and every fit takes those readings as true, so \
                 the estimates are biased; record with a wider sensor range",
                at.join(", ")
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(u: impl Fn(usize) -> f64, i: impl Fn(usize) -> f64) -> Record {
        let n = 400;
        Record {
            segments: vec![DcSegment {
                index: 2,
                label: "x".into(),
                time: (0..n).map(|k| k as f64 * 1e-3).collect(),
                voltage: (0..n).map(&u).collect(),
                current: (0..n).map(&i).collect(),
                speed: (0..n).map(|k| u(k) / 1.3).collect(),
                ..Default::default()
            }],
            ..Default::default()
        }
    }

    #[test]
    fn an_isolated_speed_glitch_is_refused_and_a_step_or_noise_is_not() {
        // Steps between levels, with noise: no glitch.
        let u = |k: usize| if k < 200 { 60.0 } else { 120.0 };
        let mut r = record(u, |_| 0.1);
        let noisy: Vec<f64> = r.segments[0]
            .speed
            .iter()
            .enumerate()
            .map(|(k, w)| w + if k % 2 == 0 { 0.3 } else { -0.3 })
            .collect();
        r.segments[0].speed = noisy;
        assert!(check_plausible(&r).is_ok());
        // One reading of an encoder counter's wrap at sample 250.
        r.segments[0].speed[250] = 5e4;
        let e = check_plausible(&r).unwrap_err();
        assert_eq!((e.segment, e.column), (2, "speed_rad_s"));
        assert!(e.reason.starts_with("sample 250 reads 50000 rad/s"), "{e}");
        assert!(e.reason.contains("glitch"), "{e}");
        // The same reading held for a while is a level, not a glitch
        // (whatever else may be wrong with it).
        for k in 250..260 {
            r.segments[0].speed[k] = 5e4;
        }
        assert!(check_speed_glitches(&r).is_ok());
    }

    #[test]
    fn a_huge_current_names_the_column_and_sample() {
        let r = record(|_| 60.0, |k| if k == 7 { 1e308 } else { 0.1 });
        let e = check_plausible(&r).unwrap_err();
        assert_eq!(e.column, "armature_current_A");
        assert_eq!(e.segment, 2);
        let text = e.to_string();
        assert!(
            text.contains("sample 7") && text.contains("1e308"),
            "{text}"
        );
    }

    #[test]
    fn a_voltage_above_any_supply_is_refused() {
        let r = record(|_| 5e5, |_| 0.1);
        assert_eq!(
            check_plausible(&r).unwrap_err().column,
            "armature_voltage_V"
        );
    }

    #[test]
    fn an_unsigned_current_under_a_reversing_voltage_is_refused() {
        let u = |k: usize| if (k / 100) % 2 == 0 { 60.0 } else { -60.0 };
        let signed = record(u, |k| 0.1 * u(k).signum());
        assert!(check_plausible(&signed).is_ok());
        let unsigned = record(u, |_| 0.1);
        let e = check_plausible(&unsigned).unwrap_err();
        assert_eq!(e.column, "armature_current_A");
        assert!(e.reason.contains("never changes sign"), "{}", e.reason);
        // One polarity only: a current of one sign is normal.
        assert!(check_plausible(&record(|_| 60.0, |_| 0.1)).is_ok());
        // A current that moves from sample to sample (a closed loop read
        // slowly) has a second-difference "noise" of its own size, yet it
        // plainly reverses: -2.5 A to +1.8 A is no magnitude reading.
        let swinging = record(u, |k| match k % 3 {
            0 => 1.8 * u(k).signum(),
            1 => -2.5 * u(k).signum(),
            _ => 0.3,
        });
        assert!(check_plausible(&swinging).is_ok());
        // A rectified reading with noise a few percent of its peak dipping
        // below zero is still refused.
        let rectified = record(u, |k| if k % 2 == 0 { 1.0 } else { -0.05 });
        assert!(check_plausible(&rectified).is_err());
    }

    #[test]
    fn a_reversed_current_or_speed_is_refused_by_column() {
        let u = |k: usize| if k < 100 { 0.0 } else { 60.0 };
        assert!(check_plausible(&record(u, |k| 0.1 * u(k) / 60.0)).is_ok());
        let e = check_plausible(&record(u, |k| -0.1 * u(k) / 60.0)).unwrap_err();
        assert_eq!(e.column, "armature_current_A");
        assert!(e.reason.contains("polarity reversed"), "{}", e.reason);
        let mut r = record(u, |k| 0.1 * u(k) / 60.0);
        for w in &mut r.segments[0].speed {
            *w = -*w;
        }
        let e = check_plausible(&r).unwrap_err();
        assert_eq!(e.column, "speed_rad_s");
        // A controller braking for a while is not a reversal.
        let brake = |k: usize| if k < 300 { 60.0 } else { -60.0 };
        let r = record(brake, |k| 0.1 * brake(k) / 60.0);
        let mut r2 = r.clone();
        r2.segments[0].speed = vec![46.0; 400];
        assert!(check_plausible(&r2).is_ok());
    }

    #[test]
    fn a_clipped_current_is_warned_of_and_a_settled_maximum_is_not() {
        // A step response whose peak an ADC clips at 1.5 A.
        let i = |k: usize| 2.0 * (-(k as f64) / 50.0).exp() + 0.2;
        let r = record(|_| 60.0, |k| i(k).min(1.5));
        let w = clipped_channels(&r);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("armature_current_A") && w[0].contains("1.5 A"),
            "{}",
            w[0]
        );
        // The unclipped response, and a speed below its resolution that
        // repeats every level of a staircase alike, are not clipping.
        assert!(clipped_channels(&record(|_| 60.0, i)).is_empty());
        let mut settled = record(|_| 60.0, i);
        settled.segments[0].speed = (0..400).map(|k| (k / 100) as f64).collect();
        assert!(clipped_channels(&settled).is_empty());
        // The same speed clipped at its second level is.
        settled.segments[0].speed = (0..400).map(|k| (k / 100).min(1) as f64).collect();
        assert_eq!(clipped_channels(&settled).len(), 1);
    }
}
