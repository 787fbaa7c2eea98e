//! How well a settled level's means are known: the standard error of the
//! mean voltage, current and speed from the samples' scatter and from the
//! sensors' resolution.
//!
//! - Scatter: batch means. The tail is cut into 20 consecutive batches
//!   and the standard error is the spread of the batch means over √20.
//!   Unlike `sd/√n` this stays right when successive samples are
//!   correlated (filtered noise, ripple), as long as the correlation is
//!   shorter than a batch.
//! - Resolution of an ADC reading (voltage, current): the step between
//!   codes is found from the data (the smallest gap between distinct
//!   values, when every gap is a whole multiple of it). A quantiser whose
//!   input noise is at least half a step is dithered, and its error
//!   averages out with the noise; below that the mean can sit anywhere
//!   within ±step/2 of the truth without the scatter showing it, so a
//!   uniform ±step/2 (variance step²/12) is added.
//! - Resolution of the speed: the speed is taken to be derived from
//!   encoder counts as the bench records it (count change over each
//!   sample interval), so the mean over a window is the count change
//!   over the whole window: its quantisation error is that of two count
//!   readings, ±1/2 count each, i.e. a variance of step²/(6·n²) with the
//!   speed step (one count per sample interval) and n samples. For a
//!   speed read by an ADC (a tachometer) this is optimistic when the
//!   reading is not dithered.

use super::SettledLevel;
use crate::record::DcSegment;

/// Standard errors of a level's means.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LevelError {
    /// Of the mean voltage, V.
    pub voltage: f64,
    /// Of the mean current, A.
    pub current: f64,
    /// Of the mean speed, rad/s.
    pub speed: f64,
}

/// Batches for the batch-means standard error.
const BATCHES: usize = 20;

/// The quantisation step of `x`: the smallest gap between distinct
/// values when all gaps are whole multiples of it (to 1e-6 of the step),
/// else 0 (not quantised, or not recognisably).
pub fn resolution(x: &[f64]) -> f64 {
    let mut v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    if v.len() < 2 {
        return 0.0;
    }
    let gaps: Vec<f64> = v.windows(2).map(|w| w[1] - w[0]).collect();
    let step = gaps.iter().copied().fold(f64::INFINITY, f64::min);
    let scale = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if step <= 1e-12 * scale {
        return 0.0;
    }
    let whole = gaps.iter().all(|g| {
        let q = g / step;
        (q - q.round()).abs() <= 1e-6 * q.max(1.0)
    });
    if whole {
        step
    } else {
        0.0
    }
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

fn sd(x: &[f64]) -> f64 {
    if x.len() < 2 {
        return 0.0;
    }
    let m = mean(x);
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64).sqrt()
}

/// Standard error of the mean of `x` by batch means (plain `sd/√n` for
/// fewer than 5 samples per batch).
pub fn scatter_error(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 2 {
        return 0.0;
    }
    if n < 5 * BATCHES {
        return sd(x) / (n as f64).sqrt();
    }
    let means: Vec<f64> = (0..BATCHES)
        .map(|b| mean(&x[b * n / BATCHES..(b + 1) * n / BATCHES]))
        .collect();
    sd(&means) / (BATCHES as f64).sqrt()
}

/// Standard error of an ADC channel's mean: scatter plus, when not
/// dithered, uniform ±step/2.
pub fn adc_mean_error(x: &[f64], step: f64) -> f64 {
    let scatter = scatter_error(x);
    let quant = if sd(x) < step / 2.0 {
        step * step / 12.0
    } else {
        0.0
    };
    (scatter * scatter + quant).sqrt()
}

/// Standard error of a counter-derived speed's mean: scatter plus two
/// count readings of ±1/2 count over the window.
pub fn counter_mean_error(x: &[f64], step: f64) -> f64 {
    let scatter = scatter_error(x);
    let n = x.len().max(1) as f64;
    (scatter * scatter + step * step / (6.0 * n * n)).sqrt()
}

/// The standard errors of `level`'s means, from its segment's tail (the
/// last `level.samples` samples). Resolutions are found on the whole
/// segment, where more codes are visited.
pub fn level_error(seg: &DcSegment, level: &SettledLevel) -> LevelError {
    let n = seg.time.len();
    let start = n - level.samples.min(n);
    LevelError {
        voltage: adc_mean_error(&seg.voltage[start..], resolution(&seg.voltage)),
        current: adc_mean_error(&seg.current[start..], resolution(&seg.current)),
        speed: counter_mean_error(&seg.speed[start..], resolution(&seg.speed)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolution_is_found_from_the_codes() {
        let lsb = 800.0 / 4096.0;
        let x: Vec<f64> = [3, 5, 4, 9, 3].iter().map(|&c| c as f64 * lsb).collect();
        assert!((resolution(&x) - lsb).abs() < 1e-12);
        assert_eq!(resolution(&[1.0, 1.1234567, 2.7193]), 0.0);
        assert_eq!(resolution(&[2.0, 2.0]), 0.0);
    }

    #[test]
    fn undithered_constant_gets_uniform_half_step() {
        let step = 0.01;
        let x = vec![0.12; 400];
        assert!((adc_mean_error(&x, step) - step / 12f64.sqrt()).abs() < 1e-15);
        // Dithered (noise ≥ step/2): scatter only, shrinking as 1/√n.
        let noisy: Vec<f64> = (0..4000)
            .map(|k| ((k * 7919 % 1000) as f64 / 1000.0 - 0.5) * 4.0 * step)
            .map(|v| (v / step).round() * step)
            .collect();
        let e = adc_mean_error(&noisy, step);
        assert!(e < 0.2 * step / 12f64.sqrt(), "{e}");
    }

    #[test]
    fn counter_speed_mean_is_resolved_to_a_count_over_the_window() {
        // 33.4 counts per sample: the readings toggle between 33 and 34
        // counts; the mean over 800 samples is the count change over the
        // window, known to ±1 count.
        let count_step = 1.2566;
        let mut pos = 0.3f64;
        let x: Vec<f64> = (0..800)
            .map(|_| {
                let before = pos.floor();
                pos += 33.4;
                (pos.floor() - before) * count_step
            })
            .collect();
        let e = counter_mean_error(&x, count_step);
        assert!(((mean(&x) / count_step) - 33.4).abs() < 2.0 / 800.0);
        // Far below the naive sd/√n, which ignores the telescoping.
        assert!(e < 0.3 * sd(&x) / (800f64).sqrt(), "{e}");
    }
}
