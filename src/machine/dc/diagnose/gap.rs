//! Where the DC gap lies: the nominal model's held-out residuals split by
//! channel, by segment and along each segment's time axis (start-up,
//! transient, settled, coast-down), a spectral peak (oscillation), and the
//! residual statistics offered as evidence.

use std::collections::BTreeMap;
use std::f64::consts::TAU;

use statrs::distribution::{ChiSquared, ContinuousCDF, StudentsT};

use crate::contract::{GapRegion, RegionAxis, ResidualEvidence};
use crate::diagnose::decision::{effective_samples, median, FALSE_ALARM_RATE};

/// Held-out residuals (measured − simulated) of one segment.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct HeldOutSeries {
    /// Segment index in the record.
    pub segment: u32,
    /// Seconds since the segment's first sample.
    pub t: Vec<f64>,
    /// Current residual, A (empty for a coast-down).
    pub current: Vec<f64>,
    /// Speed residual, rad/s.
    pub speed: Vec<f64>,
    /// Whether the segment starts from rest.
    pub from_rest: bool,
    /// Whether it is a coast-down.
    pub coast: bool,
    /// NRMSE on it, the contract's (mean over its channels).
    pub nrmse: f64,
}

impl HeldOutSeries {
    /// Noise-weighted squared residual per sample (current plus speed).
    pub fn weighted_squares(&self, wi: f64, ww: f64) -> Vec<f64> {
        (0..self.speed.len())
            .map(|k| {
                let c = self.current.get(k).map_or(0.0, |r| (r * wi).powi(2));
                c + (self.speed[k] * ww).powi(2)
            })
            .collect()
    }
}

/// Measured signals beside a held-out series, for correlations.
#[derive(Debug, Clone, Copy)]
pub struct Measured<'a> {
    /// Armature voltage, V.
    pub voltage: &'a [f64],
    /// Armature current, A.
    pub current: &'a [f64],
    /// Speed, rad/s.
    pub speed: &'a [f64],
}

/// The gap's location: regions (largest share first), channel and segment
/// shares, evidence, and the oscillation frequency when there is one.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GapLocation {
    /// Regions, largest share first.
    pub regions: Vec<GapRegion>,
    /// Share per channel.
    pub channels: BTreeMap<String, f64>,
    /// Share per segment index.
    pub segments: BTreeMap<String, f64>,
    /// Residual statistics.
    pub evidence: Vec<ResidualEvidence>,
    /// Frequency of a significant spectral peak of the residual, Hz.
    pub oscillation_hz: Option<f64>,
}

const CHANNELS: [&str; 2] = ["armature_current", "speed"];

/// Locate the gap in `series` (weights `1/σ` per channel), with the
/// transient taken as the first `transient_s` seconds after each step.
pub fn locate(
    series: &[HeldOutSeries],
    measured: &[Measured],
    weights: [f64; 2],
    transient_s: f64,
    dt: f64,
) -> GapLocation {
    let mut loc = GapLocation::default();
    let mut total = 0.0;
    let mut per_channel = [0.0f64; 2];
    // (channel, segment, label, from, to, energy)
    let mut parts: Vec<(usize, u32, &str, f64, f64, f64)> = Vec::new();
    for s in series {
        let mut seg_sum = 0.0;
        for (c, res) in [&s.current, &s.speed].into_iter().enumerate() {
            if res.is_empty() {
                continue;
            }
            let w2 = weights[c] * weights[c];
            let (mut early, mut late) = (0.0, 0.0);
            for (k, r) in res.iter().enumerate() {
                let e = r * r * w2;
                if s.coast || s.t[k] < transient_s {
                    early += e;
                } else {
                    late += e;
                }
            }
            let end = *s.t.last().unwrap_or(&0.0);
            let cut = transient_s.min(end);
            if s.coast {
                parts.push((c, s.segment, "coast_down", 0.0, end, early));
            } else {
                let label = if s.from_rest { "start_up" } else { "transient" };
                parts.push((c, s.segment, label, 0.0, cut, early));
                if end > cut {
                    parts.push((c, s.segment, "settled", cut, end, late));
                }
            }
            per_channel[c] += early + late;
            seg_sum += early + late;
        }
        total += seg_sum;
        loc.segments.insert(s.segment.to_string(), seg_sum);
    }
    let total = total.max(f64::MIN_POSITIVE);
    for v in loc.segments.values_mut() {
        *v /= total;
    }
    for (c, name) in CHANNELS.iter().enumerate() {
        loc.channels
            .insert((*name).to_string(), per_channel[c] / total);
    }
    loc.regions = parts
        .into_iter()
        .map(|(c, seg, label, from, to, e)| GapRegion {
            channel: CHANNELS[c].into(),
            axis: RegionAxis::Time,
            from,
            to,
            label: label.into(),
            share: e / total,
            segment: Some(seg),
            voltage: None,
        })
        .collect();

    // Oscillation: a significant spectral peak of the step segments'
    // residuals, per channel.
    for (c, name) in CHANNELS.iter().enumerate() {
        let pieces: Vec<&[f64]> = series
            .iter()
            .filter(|s| !s.coast)
            .map(|s| if c == 0 { &s.current[..] } else { &s.speed[..] })
            .filter(|r| r.len() > 64)
            .collect();
        if let Some(peak) = spectral_peak(&pieces, dt) {
            loc.evidence.push(ResidualEvidence {
                channel: (*name).into(),
                statistic: "spectral_peak_hz".into(),
                value: peak.hz,
                p_value: Some(peak.p_value),
            });
            if peak.p_value < FALSE_ALARM_RATE {
                let end = series
                    .iter()
                    .filter(|s| !s.coast)
                    .map(|s| *s.t.last().unwrap_or(&0.0))
                    .fold(0.0, f64::max);
                loc.regions.push(GapRegion {
                    channel: (*name).into(),
                    axis: RegionAxis::Time,
                    from: 0.0,
                    to: end,
                    label: "oscillation".into(),
                    share: peak.band_share * per_channel[c] / total,
                    segment: None,
                    voltage: None,
                });
                if loc.oscillation_hz.is_none() || c == 1 {
                    loc.oscillation_hz = Some(peak.hz);
                }
            }
        }
    }
    loc.regions
        .sort_by(|a, b| b.share.total_cmp(&a.share).then(a.label.cmp(&b.label)));
    loc.evidence.extend(evidence(series, measured, weights));
    loc
}

/// A spectral peak of a residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpectralPeak {
    /// Its frequency, Hz.
    pub hz: f64,
    /// p-value of "no peak": the largest of `M` exponential ordinates
    /// against the local background.
    pub p_value: f64,
    /// Share of the residual's energy within ±2 bins of the peak.
    pub band_share: f64,
}

/// The summed periodograms of `pieces` at `freqs` (Goertzel, each piece
/// about its mean, divided by its length), and the pieces' summed energy
/// about their means.
fn periodogram(pieces: &[&[f64]], freqs: &[f64], dt: f64) -> (Vec<f64>, f64) {
    let mut power = vec![0.0; freqs.len()];
    let mut energy = 0.0;
    // Goertzel, `GOERTZEL_LANES` frequencies a pass over the piece: each
    // frequency's recursion is serial, several side by side are not.
    let coeffs: Vec<f64> = freqs.iter().map(|f| 2.0 * (TAU * f * dt).cos()).collect();
    for piece in pieces {
        let mean = piece.iter().sum::<f64>() / piece.len() as f64;
        energy += piece.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
        for (power, coeff) in power
            .chunks_mut(GOERTZEL_LANES)
            .zip(coeffs.chunks(GOERTZEL_LANES))
        {
            let mut c = [0.0; GOERTZEL_LANES];
            c[..coeff.len()].copy_from_slice(coeff);
            let (mut s1, mut s2) = ([0.0; GOERTZEL_LANES], [0.0; GOERTZEL_LANES]);
            for v in piece.iter() {
                let x = v - mean;
                for j in 0..GOERTZEL_LANES {
                    let s0 = x + c[j] * s1[j] - s2[j];
                    s2[j] = s1[j];
                    s1[j] = s0;
                }
            }
            for (j, p) in power.iter_mut().enumerate() {
                *p += (s1[j] * s1[j] + s2[j] * s2[j] - c[j] * s1[j] * s2[j]) / piece.len() as f64;
            }
        }
    }
    (power, energy)
}

/// Frequencies of [`spectral_peak`] run side by side in one pass.
const GOERTZEL_LANES: usize = 8;

/// The strongest local peak of the summed periodograms of `pieces`
/// (sample interval `dt`) between 5 Hz and a quarter of the sampling rate,
/// judged against the median of its neighbourhood (half to twice its
/// frequency), so the smooth low-frequency spectrum of a transient misfit
/// does not count as a peak.
pub fn spectral_peak(pieces: &[&[f64]], dt: f64) -> Option<SpectralPeak> {
    if pieces.is_empty() {
        return None;
    }
    let fs = 1.0 / dt;
    let f_hi = (fs / 4.0).min(400.0);
    let step = 1.0;
    let freqs: Vec<f64> = (0..)
        .map(|k| 5.0 + k as f64 * step)
        .take_while(|&f| f <= f_hi)
        .collect();
    if freqs.len() < 8 {
        return None;
    }
    let (power, energy) = periodogram(pieces, &freqs, dt);
    let mut best: Option<(usize, f64)> = None;
    for k in 2..freqs.len() - 2 {
        let local_max = power[k] >= power[k - 1] && power[k] >= power[k + 1];
        if !local_max {
            continue;
        }
        let f = freqs[k];
        let mut hood: Vec<f64> = freqs
            .iter()
            .zip(&power)
            .filter(|(g, _)| **g >= f / 2.0 && **g <= 2.0 * f && (**g - f).abs() > 3.0 * step)
            .map(|(_, p)| *p)
            .collect();
        if hood.len() < 6 {
            continue;
        }
        let background = median(&mut hood).unwrap_or(0.0) / std::f64::consts::LN_2;
        if background <= 0.0 {
            continue;
        }
        let g = power[k] / background;
        if best.is_none_or(|(_, bg)| g > bg) {
            best = Some((k, g));
        }
    }
    let (k, g) = best?;
    // Sum over pieces of exponentials is a gamma; treat the sum as one
    // exponential of the pooled mean (conservative for several pieces).
    let p = (freqs.len() as f64 * (-g).exp()).min(1.0);
    let band: f64 = power[k.saturating_sub(2)..(k + 3).min(power.len())]
        .iter()
        .sum();
    // Periodogram ordinates at 1 Hz spacing over a piece of T seconds
    // carry about 2/(T·fs) of the piece's energy per unit: normalise by
    // the total so the share stays in [0, 1].
    let spectral_total: f64 = power.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let share = (band / spectral_total).min(1.0) * (spectral_total / energy.max(1e-300)).min(1.0);
    Some(SpectralPeak {
        hz: freqs[k],
        p_value: p,
        band_share: share.clamp(0.0, 1.0),
    })
}

fn corr(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len().min(b.len());
    if n < 3 {
        return None;
    }
    let ma = a[..n].iter().sum::<f64>() / n as f64;
    let mb = b[..n].iter().sum::<f64>() / n as f64;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for k in 0..n {
        let (x, y) = (a[k] - ma, b[k] - mb);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    (saa > 0.0 && sbb > 0.0).then(|| sab / (saa * sbb).sqrt())
}

fn corr_p(r: f64, n_eff: f64) -> f64 {
    if n_eff <= 3.0 || r.abs() >= 1.0 {
        return if r.abs() >= 1.0 { 0.0 } else { 1.0 };
    }
    let t = r.abs() * ((n_eff - 2.0) / (1.0 - r * r)).sqrt();
    let d = StudentsT::new(0.0, 1.0, n_eff - 2.0).expect("dof > 1");
    (2.0 * (1.0 - d.cdf(t))).min(1.0)
}

/// Ljung–Box statistic over lags 1..=20, pooled over pieces, and its
/// p-value (χ² with 20 degrees of freedom).
pub fn ljung_box(pieces: &[&[f64]]) -> Option<(f64, f64)> {
    const LAGS: usize = 20;
    let mut q = 0.0;
    let mut used = false;
    for piece in pieces {
        let n = piece.len();
        if n <= 2 * LAGS {
            continue;
        }
        let mean = piece.iter().sum::<f64>() / n as f64;
        let var: f64 = piece.iter().map(|v| (v - mean).powi(2)).sum();
        if var <= 0.0 {
            continue;
        }
        for k in 1..=LAGS {
            let c: f64 = (k..n)
                .map(|t| (piece[t] - mean) * (piece[t - k] - mean))
                .sum();
            let rho = c / var;
            q += n as f64 * (n as f64 + 2.0) * rho * rho / (n - k) as f64;
        }
        used = true;
    }
    if !used {
        return None;
    }
    let dof = (LAGS * pieces.iter().filter(|p| p.len() > 2 * LAGS).count()) as f64;
    let d = ChiSquared::new(dof).ok()?;
    Some((q, 1.0 - d.cdf(q)))
}

fn evidence(series: &[HeldOutSeries], measured: &[Measured], w: [f64; 2]) -> Vec<ResidualEvidence> {
    let mut out = Vec::new();
    for (c, name) in CHANNELS.iter().enumerate() {
        let pieces: Vec<&[f64]> = series
            .iter()
            .map(|s| if c == 0 { &s.current[..] } else { &s.speed[..] })
            .filter(|r| !r.is_empty())
            .collect();
        if let Some((q, p)) = ljung_box(&pieces) {
            out.push(ResidualEvidence {
                channel: (*name).into(),
                statistic: "whiteness".into(),
                value: q,
                p_value: Some(p),
            });
        }
        let (mut r, mut u, mut sw, mut ai, mut t) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (s, m) in series.iter().zip(measured) {
            let res = if c == 0 { &s.current } else { &s.speed };
            for (k, rv) in res.iter().enumerate().take(m.voltage.len()) {
                r.push(rv * w[c]);
                u.push(m.voltage[k]);
                sw.push(m.speed[k].signum());
                ai.push(m.current[k].abs());
                t.push(s.t[k]);
            }
        }
        let n_eff = effective_samples(&r);
        for (stat, x) in [
            ("corr_input", &u),
            ("corr_sign_speed", &sw),
            ("corr_abs_current", &ai),
            ("corr_time", &t),
        ] {
            if let Some(v) = corr(&r, x) {
                out.push(ResidualEvidence {
                    channel: (*name).into(),
                    statistic: stat.into(),
                    value: v,
                    p_value: Some(corr_p(v, n_eff)),
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The frequencies side by side compute what one at a time did, to
    /// the bit (the recursion's operations in their order, no FMA).
    #[test]
    fn the_periodogram_is_one_frequency_at_a_time() {
        let a: Vec<f64> = (0..997)
            .map(|k| (k as f64 * 0.37).sin() + 1e-3 * (k % 7) as f64)
            .collect();
        let b: Vec<f64> = (0..333).map(|k| (k as f64 * 1.3).cos() * 2.0).collect();
        let pieces = [a.as_slice(), b.as_slice()];
        let (dt, freqs): (f64, Vec<f64>) = (5e-4, (0..13).map(|k| 5.0 + 31.0 * k as f64).collect());
        let (power, _) = periodogram(&pieces, &freqs, dt);
        for (fi, &f) in freqs.iter().enumerate() {
            let mut expect = 0.0;
            for piece in pieces {
                let mean = piece.iter().sum::<f64>() / piece.len() as f64;
                let coeff = 2.0 * (TAU * f * dt).cos();
                let (mut s1, mut s2) = (0.0, 0.0);
                for v in piece.iter() {
                    let s0 = (v - mean) + coeff * s1 - s2;
                    s2 = s1;
                    s1 = s0;
                }
                expect += (s1 * s1 + s2 * s2 - coeff * s1 * s2) / piece.len() as f64;
            }
            assert_eq!(power[fi].to_bits(), expect.to_bits(), "at {f} Hz");
        }
    }
    use crate::diagnose::decision::tests::noise;

    #[test]
    fn a_ringing_residual_has_a_peak_and_white_noise_has_none() {
        let dt = 5e-4;
        let white = noise(1, 2000);
        let p = spectral_peak(&[&white], dt).unwrap();
        assert!(p.p_value > FALSE_ALARM_RATE, "{p:?}");
        let ringing: Vec<f64> = white
            .iter()
            .enumerate()
            .map(|(k, v)| {
                v + 2.0 * (TAU * 37.0 * k as f64 * dt).sin() * (-(k as f64) * dt / 0.3).exp()
            })
            .collect();
        let p = spectral_peak(&[&ringing], dt).unwrap();
        assert!(p.p_value < 1e-6 && (p.hz - 37.0).abs() <= 1.0, "{p:?}");
        let decay: Vec<f64> = white
            .iter()
            .enumerate()
            .map(|(k, v)| v + 30.0 * (-(k as f64) * dt / 0.05).exp())
            .collect();
        let p = spectral_peak(&[&decay], dt).unwrap();
        assert!(
            p.p_value > FALSE_ALARM_RATE,
            "smooth misfit is no peak: {p:?}"
        );
    }

    #[test]
    fn ljung_box_tells_white_from_coloured() {
        let white = noise(2, 3000);
        let (_, p) = ljung_box(&[&white]).unwrap();
        assert!(p > 0.001);
        let coloured: Vec<f64> = white.windows(5).map(|w| w.iter().sum()).collect();
        let (_, p) = ljung_box(&[&coloured]).unwrap();
        assert!(p < 1e-6);
    }

    #[test]
    fn shares_split_by_region_and_sum_to_one() {
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * 1e-3).collect();
        let s = HeldOutSeries {
            segment: 2,
            t: t.clone(),
            current: t.iter().map(|&x| if x < 0.1 { 1.0 } else { 0.0 }).collect(),
            speed: vec![0.0; 1000],
            from_rest: false,
            coast: false,
            nrmse: 0.1,
        };
        let m = Measured {
            voltage: &t,
            current: &t,
            speed: &t,
        };
        let loc = locate(&[s], &[m], [1.0, 1.0], 0.2, 1e-3);
        assert_eq!(loc.regions[0].label, "transient");
        assert!((loc.regions[0].share - 1.0).abs() < 1e-12);
        let sum: f64 = loc
            .regions
            .iter()
            .filter(|r| r.label != "oscillation")
            .map(|r| r.share)
            .sum();
        assert!((sum - 1.0).abs() < 1e-12);
        assert!((loc.channels["armature_current"] - 1.0).abs() < 1e-12);
    }
}
