//! Normalised root-mean-square error, as the data contract defines it.

/// ‖y − ŷ‖ / ‖y − mean(y)‖ over the common length; `None` when the
/// measurement is constant (the ratio is undefined) or empty.
pub fn nrmse(measured: &[f64], simulated: &[f64]) -> Option<f64> {
    let n = measured.len().min(simulated.len());
    if n == 0 {
        return None;
    }
    let y = &measured[..n];
    let mean = y.iter().sum::<f64>() / n as f64;
    let err: f64 = y.iter().zip(simulated).map(|(a, b)| (a - b).powi(2)).sum();
    let spread: f64 = y.iter().map(|a| (a - mean).powi(2)).sum();
    (spread > 0.0).then(|| (err / spread).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn perfect_fit_is_zero_and_mean_model_is_one() {
        let y = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(nrmse(&y, &y), Some(0.0));
        assert!((nrmse(&y, &[2.5; 4]).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(nrmse(&[1.0, 1.0], &[0.0, 0.0]), None);
    }
}
