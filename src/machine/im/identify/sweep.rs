//! Slip-sweep data as induction-machine identification sees it: one
//! operating point per slip (line voltage, line current, input power), the
//! model's prediction of those points with its derivatives, and a
//! simulator for tests and benchmarks.

use rand::Rng;
use rand_distr::{Distribution, Normal};

use super::error::SweepError;
use super::standard_tests::temperature_factor;
use crate::model::{Connection, ImCircuit, ImParam, ImSupply, C64};

/// One averaged operating point of a sweep, line quantities, SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepPoint {
    /// Segment (one sweep at one supply voltage) the point belongs to.
    pub segment: u32,
    /// Slip, 0 (synchronous) to 1 (locked rotor).
    pub slip: f64,
    /// RMS line-to-line voltage, V.
    pub line_voltage: f64,
    /// RMS line current, A.
    pub line_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Shaft torque where a torque sensor exists, N·m.
    pub torque: Option<f64>,
    /// Winding temperature where a thermometer read it, °C.
    pub winding_temperature: Option<f64>,
}

/// A slip sweep (one or several segments) of one machine.
#[derive(Debug, Clone, PartialEq)]
pub struct SlipSweep {
    /// Winding connection, which maps line to phase quantities.
    pub connection: Connection,
    /// Supply frequency, Hz, where known.
    pub frequency: Option<f64>,
    /// The operating points.
    pub points: Vec<SweepPoint>,
    /// The winding temperature the fitted `Rs` is at, °C, where every
    /// point has one ([`SlipSweep::rs_scale`]); kept by a subset of the
    /// points, so that every fold's `Rs` is at the same temperature.
    pub reference_temperature: Option<f64>,
}

/// Which measured curves a fit uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channels {
    /// Line current only (the paper's Eq. 15 with `I(s)`).
    Current,
    /// Line current and input power (the paper's Eq. 25).
    CurrentAndPower,
}

impl Channels {
    /// Whether the power curve is used.
    pub fn uses_power(self) -> bool {
        self == Channels::CurrentAndPower
    }
}

/// Measurement noise for [`SlipSweep::simulate`]: Gaussian, independent per
/// reading; relative parts are fractions of the reading.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SweepNoise {
    /// σ of the voltage reading as a fraction of it.
    pub voltage_relative: f64,
    /// σ of the current reading as a fraction of it.
    pub current_relative: f64,
    /// σ of the power reading as a fraction of it.
    pub power_relative: f64,
    /// σ added to the current reading, A.
    pub current_absolute: f64,
    /// σ added to the power reading, W.
    pub power_absolute: f64,
}

impl SweepNoise {
    /// The same relative σ on voltage, current and power.
    pub fn relative(sigma: f64) -> SweepNoise {
        SweepNoise {
            voltage_relative: sigma,
            current_relative: sigma,
            power_relative: sigma,
            ..SweepNoise::default()
        }
    }
}

/// `n` slips from `s_min` to 1, denser near 0 where the curves bend
/// (quadratic spacing).
pub fn slip_grid(n: usize, s_min: f64) -> Vec<f64> {
    match n {
        0 => Vec::new(),
        1 => vec![1.0],
        _ => (0..n)
            .map(|k| {
                let x = k as f64 / (n - 1) as f64;
                s_min + (1.0 - s_min) * x * x
            })
            .collect(),
    }
}

fn gaussian(sigma: f64, rng: &mut impl Rng) -> f64 {
    if sigma > 0.0 {
        Normal::new(0.0, sigma).map_or(0.0, |n| n.sample(rng))
    } else {
        0.0
    }
}

/// Simulation with a generator of its own, for tests.
#[cfg(test)]
impl SlipSweep {
    /// [`SlipSweep::simulate`] of segment 0 with a generator seeded `seed`.
    pub(crate) fn simulate_seeded(
        circuit: &ImCircuit,
        supply: &ImSupply,
        slips: &[f64],
        noise: &SweepNoise,
        seed: u64,
    ) -> SlipSweep {
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        SlipSweep::simulate(circuit, supply, slips, noise, 0, &mut rng)
    }

    /// The points as a record holds them, at `frequency` Hz, speed not
    /// given.
    pub(crate) fn operating_points(&self, frequency: f64) -> Vec<crate::record::OperatingPoint> {
        self.points
            .iter()
            .map(|p| crate::record::OperatingPoint {
                segment: p.segment,
                slip: p.slip,
                line_voltage: p.line_voltage,
                line_current: p.line_current,
                input_power: p.input_power,
                speed: f64::NAN,
                frequency,
                torque: None,
                winding_temperature: None,
            })
            .collect()
    }
}

impl SlipSweep {
    /// Simulate one segment: the circuit on `supply` at each slip, with
    /// `noise` on the readings.
    pub fn simulate(
        circuit: &ImCircuit,
        supply: &ImSupply,
        slips: &[f64],
        noise: &SweepNoise,
        segment: u32,
        rng: &mut impl Rng,
    ) -> SlipSweep {
        let points = slips
            .iter()
            .map(|&s| {
                let op = circuit.operating_point(supply, s);
                SweepPoint {
                    segment,
                    slip: s,
                    line_voltage: op.line_voltage * (1.0 + gaussian(noise.voltage_relative, rng)),
                    line_current: op.line_current * (1.0 + gaussian(noise.current_relative, rng))
                        + gaussian(noise.current_absolute, rng),
                    input_power: op.input_power * (1.0 + gaussian(noise.power_relative, rng))
                        + gaussian(noise.power_absolute, rng),
                    torque: Some(op.torque),
                    winding_temperature: None,
                }
            })
            .collect();
        SlipSweep {
            connection: supply.connection,
            frequency: Some(supply.frequency),
            points,
            reference_temperature: None,
        }
    }

    /// Append the points of another sweep of the same machine.
    pub fn extend(&mut self, other: SlipSweep) {
        self.points.extend(other.points);
    }

    /// Check every point is usable; the error names the point.
    pub fn validate(&self) -> Result<(), SweepError> {
        if self.points.is_empty() {
            return Err(SweepError::Empty);
        }
        for (k, p) in self.points.iter().enumerate() {
            let bad = |field: &'static str, v: f64, why: &'static str| {
                Err(SweepError::BadPoint {
                    index: k,
                    segment: p.segment,
                    slip: p.slip,
                    field,
                    value: v,
                    why,
                })
            };
            if !(p.slip.is_finite() && (0.0..=1.0).contains(&p.slip)) {
                return bad("slip", p.slip, "is outside [0, 1]");
            }
            if !(p.line_voltage.is_finite() && p.line_voltage > 0.0) {
                return bad("line_voltage", p.line_voltage, "is not a finite number > 0");
            }
            if !(p.line_current.is_finite() && p.line_current > 0.0) {
                return bad("line_current", p.line_current, "is not a finite number > 0");
            }
            if !p.input_power.is_finite() {
                return bad("input_power", p.input_power, "is not a finite number");
            }
            // A temperature scales Rs per point: one in kelvin (or not a
            // number) would scale it wrongly, not merely add noise.
            if let Some(t) = p.winding_temperature {
                if let Some(why) = crate::record::implausible_temperature(t) {
                    return bad("winding_temperature", t, why);
                }
            }
        }
        Ok(())
    }

    /// Per-phase view of the points.
    pub fn phase_data(&self) -> PhaseData {
        let c = self.connection;
        PhaseData {
            slip: self.points.iter().map(|p| p.slip).collect(),
            voltage: self
                .points
                .iter()
                .map(|p| c.phase_voltage(p.line_voltage))
                .collect(),
            current: self
                .points
                .iter()
                .map(|p| c.phase_current(p.line_current))
                .collect(),
            power: self.points.iter().map(|p| p.input_power).collect(),
            rs_scale: self.rs_scale(),
        }
    }

    /// Each point's stator resistance over the one at
    /// [`SlipSweep::reference_temperature`] (copper's α between the two),
    /// where every point has a winding temperature; empty (one `Rs` for
    /// all) where not.
    pub fn rs_scale(&self) -> Vec<f64> {
        let temperatures: Option<Vec<f64>> =
            self.points.iter().map(|p| p.winding_temperature).collect();
        match (self.reference_temperature, temperatures) {
            (Some(reference), Some(t)) => t
                .iter()
                .map(|t| temperature_factor(Some(reference), Some(*t)))
                .collect(),
            _ => Vec::new(),
        }
    }

    /// The first point's winding temperature where every point has one:
    /// the reference of [`SlipSweep::rs_scale`].
    pub fn first_temperature(points: &[SweepPoint]) -> Option<f64> {
        let all = points.iter().all(|p| p.winding_temperature.is_some());
        points
            .first()
            .and_then(|p| p.winding_temperature)
            .filter(|_| all)
    }

    /// What the winding thermometer read over the points, °C: the first
    /// point's reading that has one, the lowest and highest, and how many
    /// points have one (all of them: [`SlipSweep::rs_scale`] scales each
    /// point's `Rs`); `None` where no point has one.
    pub fn thermometer(&self) -> Option<(f64, [f64; 2], usize)> {
        let t: Vec<f64> = self
            .points
            .iter()
            .filter_map(|p| p.winding_temperature)
            .collect();
        let range = t
            .iter()
            .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], t| {
                [lo.min(*t), hi.max(*t)]
            });
        Some((*t.first()?, range, t.len()))
    }
}

/// A sweep per phase: what the per-phase circuit predicts.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PhaseData {
    /// Slip of each point.
    pub slip: Vec<f64>,
    /// Phase (winding) voltage, V.
    pub voltage: Vec<f64>,
    /// Phase (winding) current, A.
    pub current: Vec<f64>,
    /// Three-phase input power, W.
    pub power: Vec<f64>,
    /// Each point's stator resistance over the fitted `Rs` (copper's, at
    /// the point's winding temperature: [`SlipSweep::rs_scale`]); empty
    /// where the fit takes one `Rs` for every point.
    pub rs_scale: Vec<f64>,
}

impl PhaseData {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.slip.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.slip.is_empty()
    }

    /// Every value divided by its per-unit base (`z_base = v_base/i_base`,
    /// power base `3·v_base·i_base`).
    pub fn per_unit(&self, v_base: f64, i_base: f64) -> PhaseData {
        let p_base = 3.0 * v_base * i_base;
        PhaseData {
            slip: self.slip.clone(),
            voltage: self.voltage.iter().map(|v| v / v_base).collect(),
            current: self.current.iter().map(|i| i / i_base).collect(),
            power: self.power.iter().map(|p| p / p_base).collect(),
            rs_scale: self.rs_scale.clone(),
        }
    }

    /// Every `stride`-th point, from the first.
    pub fn every(&self, stride: usize) -> PhaseData {
        let stride = stride.max(1);
        let pick = |v: &[f64]| v.iter().step_by(stride).copied().collect::<Vec<f64>>();
        PhaseData {
            slip: pick(&self.slip),
            voltage: pick(&self.voltage),
            current: pick(&self.current),
            power: pick(&self.power),
            rs_scale: pick(&self.rs_scale),
        }
    }

    /// The circuit as point `k` sees it: `Rs` scaled to the point's
    /// winding temperature where the data carry one.
    fn circuit_at(&self, c: &ImCircuit, k: usize) -> ImCircuit {
        match self.rs_scale.get(k) {
            Some(f) => ImCircuit { rs: c.rs * f, ..*c },
            None => *c,
        }
    }

    /// [`predict`] at point `k`.
    pub fn predict(&self, c: &ImCircuit, k: usize) -> (f64, f64) {
        predict(&self.circuit_at(c, k), self.slip[k], self.voltage[k])
    }

    /// [`predict_gradient`] at point `k`, the derivatives with respect to
    /// the fitted `Rs` (at the reference temperature).
    pub fn predict_gradient(
        &self,
        c: &ImCircuit,
        k: usize,
        params: &[ImParam],
    ) -> (f64, f64, Vec<f64>, Vec<f64>) {
        let (i, p, mut di, mut dp) = predict_gradient(
            &self.circuit_at(c, k),
            self.slip[k],
            self.voltage[k],
            params,
        );
        let rs = params.iter().position(|q| *q == ImParam::Rs);
        if let (Some(f), Some(q)) = (self.rs_scale.get(k), rs) {
            di[q] *= f;
            dp[q] *= f;
        }
        (i, p, di, dp)
    }
}

/// Model phase current and three-phase power at slip `s`, phase voltage `v`.
pub fn predict(c: &ImCircuit, s: f64, v: f64) -> (f64, f64) {
    terminal(c.impedance(s).inv(), v)
}

/// Current and power at phase voltage `v` from the input admittance `y`.
#[inline(always)]
fn terminal(y: C64, v: f64) -> (f64, f64) {
    (v * modulus(y), 3.0 * v * v * y.re)
}

/// `|z|` as `√(re² + im²)`: a machine's impedances and admittances are
/// far from the squares' overflow and underflow, so libm's `hypot` (what
/// `Complex::norm` calls, a tenth of the circuit fit's time) guards
/// nothing here.
#[inline(always)]
fn modulus(z: C64) -> f64 {
    z.norm_sqr().sqrt()
}

/// `dI/dθ` from the impedance `z`, `minus_v_zn3 = −V/|Z|³` and
/// `dz = dZ/dθ`.
#[inline(always)]
fn current_derivative(minus_v_zn3: f64, z: C64, dz: C64) -> f64 {
    minus_v_zn3 * (z.conj() * dz).re
}

/// `−V/|Z|³`, shared by the current's derivatives at one point.
#[inline(always)]
fn minus_v_over_cube(v: f64, zn: f64) -> f64 {
    -v / (zn * zn * zn)
}

/// `dP/dθ` from `z2inv = 1/Z²` and `dz = dZ/dθ`.
#[inline(always)]
fn power_derivative(v: f64, z2inv: C64, dz: C64) -> f64 {
    -3.0 * v * v * (dz * z2inv).re
}

/// [`predict`] with the derivatives of current and power with respect to
/// each of `params`: `dI = −V·Re(conj(Z)·dZ)/|Z|³`, `dP = −3V²·Re(dZ/Z²)`.
pub fn predict_gradient(
    c: &ImCircuit,
    s: f64,
    v: f64,
    params: &[ImParam],
) -> (f64, f64, Vec<f64>, Vec<f64>) {
    let mut di = vec![0.0; params.len()];
    let mut dp = vec![0.0; params.len()];
    let (i, p) = predict_gradient_into(c, s, v, params, &mut di, &mut dp);
    (i, p, di, dp)
}

/// Most elements of any model (for the stack buffers of
/// [`predict_gradient_into`]).
pub const MAX_PARAMS: usize = 10;

/// [`predict_gradient`] without allocating: the derivatives go to `di`
/// and `dp` (at least `params.len()` long, at most [`MAX_PARAMS`]).
pub fn predict_gradient_into(
    c: &ImCircuit,
    s: f64,
    v: f64,
    params: &[ImParam],
    di: &mut [f64],
    dp: &mut [f64],
) -> (f64, f64) {
    let mut dz = [C64::new(0.0, 0.0); MAX_PARAMS];
    let n = params.len().min(MAX_PARAMS);
    let z = c.impedance_gradient_into(s, &params[..n], &mut dz[..n]);
    let zn = modulus(z);
    let y = z.inv();
    let z2inv = y * y;
    let minus_v_zn3 = minus_v_over_cube(v, zn);
    for k in 0..n {
        di[k] = current_derivative(minus_v_zn3, z, dz[k]);
        dp[k] = power_derivative(v, z2inv, dz[k]);
    }
    (v / zn, 3.0 * v * v * y.re)
}

/// Buffers of [`predict_all`] and [`predict_gradients_all`], kept between
/// calls: the impedances of the last call, per point, and working space.
#[derive(Debug, Default)]
pub(super) struct PredictScratch {
    z_ag: Vec<C64>,
    z: Vec<C64>,
    y: Vec<C64>,
    minus_v_zn3: Vec<f64>,
    z2inv: Vec<C64>,
    minus_z_ag2: Vec<C64>,
    dz: Vec<C64>,
}

impl PredictScratch {
    /// The impedances of `c` at every point of `data`.
    fn impedances(&mut self, c: &ImCircuit, data: &PhaseData) {
        let zero = C64::new(0.0, 0.0);
        for v in [&mut self.z_ag, &mut self.z, &mut self.y] {
            v.resize(data.len(), zero);
        }
        c.impedances_into(&data.slip, &mut self.z_ag, &mut self.z, &mut self.y);
        // Rs at each point's temperature, where the data carry one.
        let points = self.z_ag.iter().zip(&mut self.z).zip(&mut self.y);
        for (((z_ag, z), y), f) in points.zip(&data.rs_scale) {
            *z = C64::new(c.rs * f, c.xs) + z_ag;
            *y = z.inv();
        }
    }
}

/// [`predict`] at every point of `data` (the same values, to the bit):
/// currents into `i`, powers into `p`. `scratch` keeps the circuit's
/// impedances for [`predict_gradients_all`] at the same circuit.
pub(super) fn predict_all(
    c: &ImCircuit,
    data: &PhaseData,
    scratch: &mut PredictScratch,
    i: &mut [f64],
    p: &mut [f64],
) {
    scratch.impedances(c, data);
    for (((y, &v), i), p) in scratch.y.iter().zip(&data.voltage).zip(i).zip(p) {
        (*i, *p) = terminal(*y, v);
    }
}

/// [`predict_gradient_into`] at every point of `data` with respect to
/// every element of the model ([`ImModel::params`](crate::model::ImModel::params)),
/// the same values to the bit: the derivative with respect to the `q`-th
/// element at point `k` into `di[q·n + k]` and `dp[q·n + k]`, `n` points.
/// `same_circuit`: the last [`predict_all`] with `scratch` was at `c`
/// (its impedances are used again).
pub(super) fn predict_gradients_all(
    c: &ImCircuit,
    data: &PhaseData,
    scratch: &mut PredictScratch,
    same_circuit: bool,
    di: &mut [f64],
    dp: &mut [f64],
) {
    let n = data.len();
    let q = c.model().params().len();
    let s = scratch;
    if !same_circuit {
        s.impedances(c, data);
    }
    s.minus_z_ag2.resize(n, C64::new(0.0, 0.0));
    s.dz.resize(q * n, C64::new(0.0, 0.0));
    c.impedance_derivatives_into(&data.slip, &s.z_ag, &mut s.minus_z_ag2, &mut s.dz);
    // dZ/dRs is each point's scale where the data carry one.
    if let Some(q) = c.model().params().iter().position(|p| *p == ImParam::Rs) {
        for (d, f) in s.dz[q * n..(q + 1) * n].iter_mut().zip(&data.rs_scale) {
            *d = C64::new(*f, 0.0);
        }
    }
    s.minus_v_zn3.clear();
    let points = s.z.iter().zip(&data.voltage);
    s.minus_v_zn3
        .extend(points.map(|(&z, &v)| minus_v_over_cube(v, modulus(z))));
    // 1/Z² from the admittance, as predict_gradient_into forms it.
    s.z2inv.clear();
    s.z2inv.extend(s.y.iter().map(|y| y * y));
    let per_element =
        s.dz.chunks_exact(n)
            .zip(di.chunks_exact_mut(n).zip(dp.chunks_exact_mut(n)));
    for (dz, (di, dp)) in per_element {
        let points =
            s.z.iter()
                .zip(&s.minus_v_zn3)
                .zip(&s.z2inv)
                .zip(&data.voltage);
        for ((((&z, &minus_v_zn3), &z2inv), &v), (dz, (di, dp))) in
            points.zip(dz.iter().zip(di.iter_mut().zip(dp.iter_mut())))
        {
            *di = current_derivative(minus_v_zn3, z, *dz);
            *dp = power_derivative(v, z2inv, *dz);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::im_fixtures::{single_cage, STAR_400V_50HZ};

    #[test]
    fn grid_is_dense_near_zero_and_ends_at_one() {
        let g = slip_grid(50, 0.002);
        assert_eq!(g.len(), 50);
        assert_eq!(g[0], 0.002);
        assert!((g[49] - 1.0).abs() < 1e-15);
        assert!(g[1] - g[0] < g[49] - g[48]);
    }

    #[test]
    fn simulated_sweep_maps_back_to_phase_values() {
        let c = single_cage(1.0, 2.0, 60.0, Some(800.0), 1.2, 2.5);
        let sw = SlipSweep::simulate_seeded(
            &c,
            &STAR_400V_50HZ,
            &slip_grid(10, 0.01),
            &SweepNoise::default(),
            1,
        );
        sw.validate().unwrap();
        let d = sw.phase_data();
        for k in 0..d.len() {
            let (i, p) = predict(&c, d.slip[k], d.voltage[k]);
            assert!((i - d.current[k]).abs() < 1e-9 && (p - d.power[k]).abs() < 1e-6);
        }
        let mut bad = sw.clone();
        bad.points[3].slip = 1.5;
        let e = bad.validate().unwrap_err();
        assert!(matches!(e, SweepError::BadPoint { index: 3, .. }), "{e:?}");
        assert!(e.to_string().contains("operating point 3"));
        // A winding temperature in kelvin would scale Rs wrongly.
        let mut kelvin = sw.clone();
        for p in &mut kelvin.points {
            p.winding_temperature = Some(25.0);
        }
        kelvin.validate().unwrap();
        kelvin.points[5].winding_temperature = Some(298.15);
        let e = kelvin.validate().unwrap_err().to_string();
        assert!(
            e.contains("operating point 5")
                && e.contains("winding_temperature")
                && e.contains("not K"),
            "{e}"
        );
    }

    #[test]
    fn prediction_gradient_matches_finite_differences() {
        let c = crate::model::SEED_DOUBLE_CAGE_PU;
        let params = c.model().params();
        for s in [0.01, 0.3, 1.0] {
            let (i, p, di, dp) = predict_gradient(&c, s, 1.0, params);
            let (i0, p0) = predict(&c, s, 1.0);
            assert!((i - i0).abs() < 1e-12 * i0 && (p - p0).abs() < 1e-12 * p0);
            for (k, &q) in params.iter().enumerate() {
                let v = c.get(q).unwrap();
                let h = 1e-6 * v;
                let (mut a, mut b) = (c, c);
                a.set(q, v + h).unwrap();
                b.set(q, v - h).unwrap();
                let (ia, pa) = predict(&a, s, 1.0);
                let (ib, pb) = predict(&b, s, 1.0);
                // Round-off of the difference is about 1e-16·I/h.
                assert!(((ia - ib) / (2.0 * h) - di[k]).abs() < 1e-6 * di[k].abs() + 1e-8 * i / v);
                assert!(((pa - pb) / (2.0 * h) - dp[k]).abs() < 1e-6 * dp[k].abs() + 1e-8 * p / v);
            }
        }
    }

    #[test]
    fn the_predictions_of_all_points_are_those_of_each_point_to_the_bit() {
        let single = single_cage(1.0, 2.0, 60.0, None, 1.2, 2.5);
        let single_fe = single_cage(1.0, 2.0, 60.0, Some(800.0), 1.2, 2.5);
        let double = crate::model::SEED_DOUBLE_CAGE_PU;
        let double_fe = ImCircuit {
            rfe: Some(40.0),
            ..double
        };
        let data = PhaseData {
            slip: vec![0.0, 0.002, 0.03, 0.2, 0.6, 1.0, 0.45],
            voltage: vec![230.0, 231.0, 229.0, 1.0, 0.9, 400.0, 120.0],
            current: vec![0.0; 7],
            power: vec![0.0; 7],
            rs_scale: Vec::new(),
        };
        let n = data.len();
        let mut scratch = PredictScratch::default();
        for c in [single, single_fe, double, double_fe] {
            let params = c.model().params();
            let q = params.len();
            let (mut i, mut p) = (vec![0.0; n], vec![0.0; n]);
            predict_all(&c, &data, &mut scratch, &mut i, &mut p);
            // After predict_all at c, and with the impedances recomputed.
            for same_circuit in [true, false] {
                let (mut di, mut dp) = (vec![0.0; q * n], vec![0.0; q * n]);
                predict_gradients_all(&c, &data, &mut scratch, same_circuit, &mut di, &mut dp);
                for k in 0..n {
                    let (s, v) = (data.slip[k], data.voltage[k]);
                    let (i1, p1) = predict(&c, s, v);
                    assert_eq!(
                        (i[k].to_bits(), p[k].to_bits()),
                        (i1.to_bits(), p1.to_bits())
                    );
                    let (_, _, di1, dp1) = predict_gradient(&c, s, v, params);
                    for e in 0..q {
                        assert_eq!(di[e * n + k].to_bits(), di1[e].to_bits(), "{c:?} {s}");
                        assert_eq!(dp[e * n + k].to_bits(), dp1[e].to_bits(), "{c:?} {s}");
                    }
                }
            }
        }
    }

    /// With each point's `Rs` scaled (its winding temperature), the
    /// point-set evaluation is the point's circuit with `Rs` scaled, and
    /// the derivative with respect to `Rs` is the point's scale times the
    /// scaled circuit's (the same values up to the order of one product).
    #[test]
    fn a_point_scaled_rs_is_that_point_circuit_and_its_derivative() {
        let data = PhaseData {
            slip: vec![0.002, 0.03, 0.2, 0.6, 1.0],
            voltage: vec![230.0, 229.0, 231.0, 230.0, 120.0],
            current: vec![0.0; 5],
            power: vec![0.0; 5],
            rs_scale: vec![1.0, 1.05, 1.1, 1.2, 1.3],
        };
        let n = data.len();
        let mut scratch = PredictScratch::default();
        for c in [
            single_cage(1.0, 2.0, 60.0, Some(800.0), 1.2, 2.5),
            crate::model::SEED_DOUBLE_CAGE_PU,
        ] {
            let params = c.model().params();
            let q = params.len();
            let (mut i, mut p) = (vec![0.0; n], vec![0.0; n]);
            predict_all(&c, &data, &mut scratch, &mut i, &mut p);
            let (mut di, mut dp) = (vec![0.0; q * n], vec![0.0; q * n]);
            predict_gradients_all(&c, &data, &mut scratch, true, &mut di, &mut dp);
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-13 * a.abs().max(b.abs());
            for k in 0..n {
                let hot = ImCircuit {
                    rs: c.rs * data.rs_scale[k],
                    ..c
                };
                let (ik, pk) = predict(&hot, data.slip[k], data.voltage[k]);
                assert_eq!((i[k], p[k]), (ik, pk));
                assert_eq!(data.predict(&c, k), (ik, pk));
                let (_, _, di1, dp1) = data.predict_gradient(&c, k, params);
                for e in 0..q {
                    assert!(close(di[e * n + k], di1[e]) && close(dp[e * n + k], dp1[e]));
                }
                // dI/dRs by central differences of the reference Rs.
                let rs = params.iter().position(|p| *p == ImParam::Rs).unwrap();
                let h = 1e-6 * c.rs;
                let at = |rs: f64| data.predict(&ImCircuit { rs, ..c }, k);
                let ((ia, pa), (ib, pb)) = (at(c.rs + h), at(c.rs - h));
                assert!(((ia - ib) / (2.0 * h) - di1[rs]).abs() < 1e-6 * di1[rs].abs());
                assert!(((pa - pb) / (2.0 * h) - dp1[rs]).abs() < 1e-6 * dp1[rs].abs());
            }
        }
    }
}
