//! A DC record that holds its whole test in one segment — a lab's single
//! CSV file of a staircase, a ramp or a closed loop — split into several,
//! so that what needs segments applies to it: the level methods need one
//! level per segment, and held-out validation and the diagnosis leave one
//! segment out at a time.
//!
//! - Where the voltage holds levels, the segment is cut just before each
//!   voltage step: every part then starts at the old level and ends on the
//!   new one, as the bench records a staircase.
//! - Otherwise (a ramp, a PRBS, a controller's command) it is cut into
//!   [`BLOCKS`] equal time blocks; each part's model response starts from
//!   the measured state at its first sample, as any segment's does.
//!
//! A record with two or more driven segments is left as it is: its
//! segments are the ones its maker chose. The split is said in the
//! record's notes, which the report lists among its warnings.

use crate::machine::dc::identify::{is_coastdown, white_noise};
use crate::record::{DcSegment, Record, SegmentKind};

/// Equal time blocks a segment without held levels is cut into.
pub const BLOCKS: usize = 4;
/// Fewest samples a part must have.
pub(crate) const MIN_PART: usize = 50;
/// Half-width of the window that judges whether the voltage is flat at a
/// sample, samples.
const FLAT_HALF_WIDTH: usize = 3;
/// Most levels a segment may hold and still be cut at its steps; more is
/// a PRBS or a controller's command, cut into blocks instead.
const MAX_LEVELS: usize = 40;
/// Noise deviations of the current a level's mean current magnitude must
/// exceed: a supply holding a level drives at least the friction's
/// current, an opened armature none.
const CARRIED_NOISE: f64 = 5.0;
/// Share of the segment's peak current it must exceed as well (a current
/// read below its resolution has no noise to compare with).
const CARRIED_PEAK: f64 = 1e-3;
/// Share of the samples up to the last level's end that held levels must
/// cover for the segment to count as a staircase.
const HELD_SHARE: f64 = 0.6;

/// The record with its one driven segment split (see the module docs), or
/// as it was. Segments are renumbered in order when one is split.
pub fn split_single_segment(mut record: Record) -> Record {
    let not_marked: Vec<usize> = record
        .segments
        .iter()
        .enumerate()
        .filter(|(_, s)| s.kind != Some(SegmentKind::DcCoastdown) && !s.time.is_empty())
        .map(|(k, _)| k)
        .collect();
    let driven: Vec<usize> = not_marked
        .iter()
        .copied()
        .filter(|&k| !is_coastdown(&record.segments[k]))
        .collect();
    // A whole test in one segment can look like a coast-down to the
    // segment-wise test (little mean current, a speed that ends low after
    // the coast-down at its end): it is cut when it holds levels.
    let (only, levels_only) = match (&driven[..], &not_marked[..]) {
        ([only], _) => (*only, false),
        ([], [only]) if record.segments.len() == 1 => (*only, true),
        _ => return record,
    };
    let seg = &record.segments[only];
    let Some((cuts, how)) = cuts(seg, levels_only) else {
        return record;
    };
    let parts = split_at(seg, &cuts);
    let note = format!(
        "the record holds its test in one driven segment ({} {}), split {how} into {} segments \
         ({}) so that the level methods, held-out validation and the diagnosis apply",
        seg.index,
        seg.label,
        parts.len(),
        crate::excerpt::listed(
            &parts
                .iter()
                .map(|p| format!("{:.3}–{:.3} s", p.time[0], p.time[p.time.len() - 1]))
                .collect::<Vec<_>>()
        )
    );
    record.segments.splice(only..=only, parts);
    for (k, s) in record.segments.iter_mut().enumerate() {
        s.index = k as u32;
    }
    record.notes.push(note);
    record
}

/// Where to cut `seg`, and how the cuts were chosen; `None` when it is too
/// short to cut, its voltage never changes, or it holds no levels and
/// `levels_only`.
fn cuts(seg: &DcSegment, levels_only: bool) -> Option<(Vec<usize>, String)> {
    let n = seg.voltage.len();
    if n < 2 * MIN_PART {
        return None;
    }
    let u = &seg.voltage;
    let (lo, hi) = u
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let range = hi - lo;
    if range.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let noise = white_noise(u);
    let threshold = (8.0 * noise).max(0.05 * range);
    if let Some(steps) = step_cuts(u, &seg.current, threshold, noise) {
        let how = match steps.len() {
            1 => "before its voltage step".to_string(),
            n => format!("before each of its {n} voltage steps"),
        };
        return Some((steps, how));
    }
    if levels_only {
        return None;
    }
    let blocks = BLOCKS.min(n / MIN_PART);
    let cuts: Vec<usize> = (1..blocks).map(|b| b * n / blocks).collect();
    let how = format!("into {blocks} equal time blocks (its voltage holds no levels to cut at)");
    Some((cuts, how))
}

/// The sample indices just before each step between held levels of `u`
/// (levels that differ by more than `threshold`; `noise` the voltage's
/// noise deviation; `i` the current), when the levels cover most of the segment and each
/// part is long enough; `None` otherwise.
fn step_cuts(u: &[f64], i: &[f64], threshold: f64, noise: f64) -> Option<Vec<usize>> {
    let n = u.len();
    let h = FLAT_HALF_WIDTH;
    let current_peak = i.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let carried_floor = (CARRIED_NOISE * white_noise(i)).max(CARRIED_PEAK * current_peak);
    let flat = |k: usize| {
        let (a, b) = (k.saturating_sub(h), (k + h).min(n - 1));
        (u[b] - u[a]).abs() < threshold
    };
    // Runs of flat samples within `threshold` of each other, at least
    // half a part long, that do not drift (a slow ramp or a coast-down's
    // decay is flat sample to sample but holds no level): (start, end).
    let mut holds: Vec<(usize, usize)> = Vec::new();
    let mut k = 0;
    while k < n {
        if !flat(k) {
            k += 1;
            continue;
        }
        let start = k;
        let (mut lo, mut hi) = (u[k], u[k]);
        while k < n && flat(k) {
            (lo, hi) = (lo.min(u[k]), hi.max(u[k]));
            if hi - lo >= threshold {
                break;
            }
            k += 1;
        }
        if let Some((a, b)) = level_within(u, start, k, threshold, noise) {
            // A supply holds a level through a current; an opened
            // armature reads the falling back-EMF without one.
            let carried = i[a..b].iter().map(|v| v.abs()).sum::<f64>() / (b - a) as f64;
            if carried > carried_floor {
                holds.push((a, b));
            }
        }
    }
    let mean = |(a, b): (usize, usize)| u[a..b].iter().sum::<f64>() / (b - a) as f64;
    // Runs at the same level (a glitch inside a hold) are one level.
    let mut levels: Vec<(usize, usize)> = Vec::new();
    for hold in holds {
        match levels.last_mut() {
            Some(last) if (mean(*last) - mean(hold)).abs() < threshold => last.1 = hold.1,
            _ => levels.push(hold),
        }
    }
    // The levels must cover most of the samples up to the last one's end
    // (a long stretch after it, a coast-down say, is a part of its own).
    let held: usize = levels.iter().map(|(a, b)| b - a).sum();
    let last_end = levels.last().map_or(0, |l| l.1);
    if levels.len() < 2 || levels.len() > MAX_LEVELS || (held as f64) < HELD_SHARE * last_end as f64
    {
        return None;
    }
    // Cut a few samples before each level ends, so that the next part
    // starts on the old level; the last level too when a long stretch
    // that holds no level follows it (a coast-down, a ramp down).
    let ends = if n - last_end >= MIN_PART {
        &levels[..]
    } else {
        &levels[..levels.len() - 1]
    };
    let cuts: Vec<usize> = ends
        .iter()
        .map(|&(_, end)| end.saturating_sub(h + 1))
        .collect();
    let mut bounds = vec![0];
    bounds.extend(&cuts);
    bounds.push(n);
    bounds
        .windows(2)
        .all(|w| w[1] >= w[0] + MIN_PART)
        .then_some(cuts)
}

/// The level `u[start..end]` holds, trimmed at both ends to the readings
/// within four noise deviations (or a thousandth of the threshold's
/// range) of its median — so that it ends where the voltage leaves it,
/// at an armature opened for a coast-down say — when it is at least half
/// a part long and does not drift: its first and last quarters' means
/// differ by less than a quarter of `threshold`.
fn level_within(
    u: &[f64],
    start: usize,
    end: usize,
    threshold: f64,
    noise: f64,
) -> Option<(usize, usize)> {
    if end - start < MIN_PART / 2 {
        return None;
    }
    let mut sorted = u[start..end].to_vec();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let near = |k: usize| (u[k] - median).abs() <= (4.0 * noise).max(0.02 * threshold);
    let (mut a, mut b) = (start, end);
    while a < b && !near(a) {
        a += 1;
    }
    while b > a && !near(b - 1) {
        b -= 1;
    }
    if b - a < MIN_PART / 2 {
        return None;
    }
    let quarter = (b - a) / 4;
    let mean = |r: std::ops::Range<usize>| u[r.clone()].iter().sum::<f64>() / r.len() as f64;
    ((mean(a..a + quarter) - mean(b - quarter..b)).abs() < 0.25 * threshold).then_some((a, b))
}

/// `seg` cut before each index of `cuts` (ascending, inside the segment).
pub(super) fn split_at(seg: &DcSegment, cuts: &[usize]) -> Vec<DcSegment> {
    let mut bounds = vec![0];
    bounds.extend(cuts);
    bounds.push(seg.time.len());
    let parts = bounds.len() - 1;
    bounds
        .windows(2)
        .enumerate()
        .map(|(p, w)| {
            let r = w[0]..w[1];
            DcSegment {
                index: seg.index,
                kind: seg.kind,
                label: format!("{} part {}/{parts}", seg.label, p + 1),
                time: seg.time[r.clone()].to_vec(),
                voltage: seg.voltage[r.clone()].to_vec(),
                current: seg.current[r.clone()].to_vec(),
                speed: seg.speed[r].to_vec(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One segment at 1 kHz: voltage `u(t)`, a first-order current and
    /// speed response to it.
    fn one_segment(n: usize, u: impl Fn(f64) -> f64) -> Record {
        let dt = 1e-3;
        let time: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let voltage: Vec<f64> = time.iter().map(|&t| u(t)).collect();
        let mut w = 0.0;
        let speed: Vec<f64> = voltage
            .iter()
            .map(|v| {
                w += (v / 1.3 - w) * dt / 0.05;
                w
            })
            .collect();
        let current = voltage
            .iter()
            .zip(&speed)
            .map(|(v, w)| (v - 1.3 * w) / 30.0 + 0.1)
            .collect();
        Record {
            segments: vec![DcSegment {
                index: 0,
                kind: Some(SegmentKind::DcStep),
                label: "lab.csv".into(),
                time,
                voltage,
                current,
                speed,
            }],
            ..Default::default()
        }
    }

    /// Assert that the first note on `split` says `text`.
    fn assert_first_note_says(split: &Record, text: &str) {
        assert!(split.notes[0].contains(text), "{}", split.notes[0]);
    }

    #[test]
    fn a_staircase_in_one_segment_is_cut_just_before_each_step() {
        let levels = [0.0, 60.0, 120.0, 248.0];
        let r = one_segment(2000, |t| levels[((t / 0.5) as usize).min(3)]);
        let split = split_single_segment(r);
        assert_eq!(split.segments.len(), 4);
        for (k, s) in split.segments.iter().enumerate() {
            assert_eq!(s.index, k as u32);
            assert_eq!(s.label, format!("lab.csv part {}/4", k + 1));
            // Each part after the first starts on the old level and holds
            // the new one at its end.
            if k > 0 {
                assert_eq!(s.voltage[0], levels[k - 1]);
            }
            assert_eq!(*s.voltage.last().unwrap(), levels[k]);
        }
        let total: usize = split.segments.iter().map(|s| s.time.len()).sum();
        assert_eq!(total, 2000);
        assert_first_note_says(&split, "before each of its 3 voltage steps");
    }

    #[test]
    fn a_coast_down_after_the_last_level_is_a_part_of_its_own() {
        let r = one_segment(2000, |t| match t {
            t if t < 0.7 => 60.0,
            t if t < 1.4 => 120.0,
            t => 120.0 * (-(t - 1.4) / 0.1).exp(),
        });
        let split = split_single_segment(r);
        assert_eq!(split.segments.len(), 3, "{:?}", split.notes);
        assert_eq!(split.segments[2].voltage[0], 120.0);
        assert!(split.segments[2].voltage.last().unwrap() < &1.0);
    }

    #[test]
    fn a_lone_coast_down_is_not_cut_into_blocks() {
        // The open armature reads the back-EMF of a rotor running down
        // from its first sample on, and carries no current.
        let mut r = one_segment(2000, |t| 120.0 * (-t / 0.3).exp());
        let seg = &mut r.segments[0];
        seg.speed = seg.voltage.iter().map(|v| v / 1.3).collect();
        for i in &mut seg.current {
            *i = 0.0;
        }
        assert!(is_coastdown(&r.segments[0]));
        assert_eq!(split_single_segment(r).segments.len(), 1);
    }

    #[test]
    fn a_ramp_is_cut_into_equal_blocks() {
        let r = one_segment(2000, |t| 100.0 * t);
        let split = split_single_segment(r);
        assert_eq!(split.segments.len(), BLOCKS);
        assert!(split.segments.iter().all(|s| s.time.len() == 500));
        assert_first_note_says(&split, "equal time blocks");
    }

    #[test]
    fn a_record_of_several_segments_or_a_constant_voltage_is_left_alone() {
        let mut two = one_segment(400, |_| 60.0);
        two.segments.push(two.segments[0].clone());
        two.segments[1].index = 1;
        let out = split_single_segment(two.clone());
        assert_eq!(out.segments, two.segments);
        assert!(out.notes.is_empty());

        let constant = one_segment(400, |_| 60.0);
        let out = split_single_segment(constant.clone());
        assert_eq!(out.segments, constant.segments);

        let short = one_segment(60, |t| if t < 0.03 { 0.0 } else { 60.0 });
        assert_eq!(split_single_segment(short).segments.len(), 1);
    }
}
