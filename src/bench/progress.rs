//! Progress reporting from the bench to whoever watches (a progress bar in
//! the CLI, nothing in tests).

/// Receives progress while a test runs.
pub trait Progress: Send + Sync {
    /// A new segment began.
    fn segment(&self, index: usize, total: usize, label: &str);
    /// Test time advanced to `t_s` seconds.
    fn tick(&self, t_s: f64);
    /// The test ended.
    fn done(&self, message: &str);
    /// An operating point of a sweep was recorded (a live display plots
    /// it). Default: ignored.
    fn operating_point(&self, _point: &crate::record::OperatingPoint) {}
    /// The plan recorded an event of `level` at test time `t_s` (a
    /// warning a person should see while the test runs). Default:
    /// ignored (it is in the record either way).
    fn event(&self, _t_s: f64, _level: crate::record::EventLevel, _message: &str) {}
}

/// Progress that goes nowhere.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn segment(&self, _: usize, _: usize, _: &str) {}
    fn tick(&self, _: f64) {}
    fn done(&self, _: &str) {}
}
