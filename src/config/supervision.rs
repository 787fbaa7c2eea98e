//! The `[supervisor]` section: what the safety supervisor enforces beyond
//! `[limits]` (power, winding temperature, stale data, bus loss, the
//! emergency-stop input). Every key has a default, so rigs without the
//! section get a working supervisor.

use serde::Deserialize;

use super::{ConfigError, Limits};

/// Raw `[supervisor]` table.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSupervisor {
    #[serde(rename = "max_power_W")]
    max_power: Option<f64>,
    stale_timeout_s: Option<f64>,
    bus_loss_timeout_s: Option<f64>,
    estop_channel: Option<String>,
    last_resort_command: Option<Vec<String>>,
    stuck_after_s: Option<f64>,
    #[serde(default)]
    thermal: RawThermal,
}

/// Raw `[supervisor.thermal]` table.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawThermal {
    #[serde(rename = "rated_current_A")]
    rated_current: Option<f64>,
    #[serde(rename = "rated_rise_K")]
    rated_rise: Option<f64>,
    time_constant_s: Option<f64>,
    #[serde(rename = "ambient_C")]
    ambient: Option<f64>,
    #[serde(rename = "max_winding_C")]
    max_winding: Option<f64>,
}

/// Default stale-data timeout, s.
pub const DEFAULT_STALE_TIMEOUT_S: f64 = 0.25;
/// Default bus-loss timeout, s.
pub const DEFAULT_BUS_LOSS_TIMEOUT_S: f64 = 0.25;
/// Default winding temperature rise at rated current, K (insulation class
/// B's rated rise).
pub const DEFAULT_RATED_RISE_K: f64 = 80.0;
/// Default winding thermal time constant, s (a small motor's winding).
pub const DEFAULT_THERMAL_TIME_CONSTANT_S: f64 = 900.0;
/// Default ambient temperature, °C.
pub const DEFAULT_AMBIENT_C: f64 = 40.0;
/// Default winding temperature limit, °C (insulation class B).
pub const DEFAULT_MAX_WINDING_C: f64 = 130.0;

/// The winding-temperature estimate from I²t: a first-order thermal model
/// whose steady-state rise is `rated_rise · (I / rated_current)²`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermalModel {
    /// Current at which the winding settles `rated_rise` above ambient, A.
    pub rated_current: f64,
    /// Steady-state rise at rated current, K.
    pub rated_rise: f64,
    /// Winding thermal time constant, s.
    pub time_constant: f64,
    /// Ambient (and starting) temperature, °C.
    pub ambient: f64,
    /// The estimate may not exceed this, °C.
    pub max_winding: f64,
}

/// The supervisor's last resort when a stage's output stays enabled after
/// the safe command and the output disable: a program run with its
/// arguments (e.g. one that opens a contactor or trips the e-stop loop).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LastResort {
    /// The program and its arguments.
    pub argv: Vec<String>,
}

/// Arguments a last-resort command may have, the program included.
pub const MAX_LAST_RESORT_ARGS: usize = 64;

/// The validated `[supervisor]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct Supervision {
    /// Largest electrical power magnitude, W.
    pub max_power: f64,
    /// A channel with no new reading for this long (data time) trips, s.
    pub stale_timeout: f64,
    /// No data at all for this long (wall clock) trips, s.
    pub bus_loss_timeout: f64,
    /// Sensor quantity of the emergency-stop input (a reading ≥ 0.5 is an
    /// emergency stop), if the rig has one.
    pub estop_channel: Option<String>,
    /// What to run when a stage's output stays enabled after the safe
    /// command and the output disable (`last_resort_command`).
    pub last_resort: Option<LastResort>,
    /// Warn when a channel holds exactly one value this long while the
    /// drive changes, s (`stuck_after_s`); `None`: no such warning.
    pub stuck_after: Option<f64>,
    /// The winding-temperature estimate.
    pub thermal: ThermalModel,
}

impl Supervision {
    /// The defaults of an absent `[supervisor]` section for a machine of
    /// `rated_current` (A) under `limits`.
    pub fn defaults(limits: &Limits, rated_current: f64) -> Supervision {
        Supervision {
            max_power: limits.max_voltage * limits.max_current,
            stale_timeout: DEFAULT_STALE_TIMEOUT_S,
            bus_loss_timeout: DEFAULT_BUS_LOSS_TIMEOUT_S,
            estop_channel: None,
            last_resort: None,
            stuck_after: None,
            thermal: ThermalModel {
                rated_current,
                rated_rise: DEFAULT_RATED_RISE_K,
                time_constant: DEFAULT_THERMAL_TIME_CONSTANT_S,
                ambient: DEFAULT_AMBIENT_C,
                max_winding: DEFAULT_MAX_WINDING_C,
            },
        }
    }
}

impl RawSupervisor {
    /// Validate against the rest of the configuration; `source` names the
    /// file in errors.
    pub(crate) fn validate(
        self,
        source: &str,
        limits: &Limits,
        nameplate: &serde_json::Value,
    ) -> Result<Supervision, ConfigError> {
        let invalid = |key: &str, reason: String| ConfigError::Invalid {
            line: None,
            path: source.to_string(),
            key: format!("supervisor.{key}"),
            reason,
        };
        let positive = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(invalid(key, format!("{v} must be a finite number > 0")))
            }
        };
        let max_power = positive(
            "max_power_W",
            self.max_power
                .unwrap_or(limits.max_voltage * limits.max_current),
        )?;
        let timeout = |key: &str, v: f64| {
            crate::bounds::supervision_timeout_s(v).map_err(|why| invalid(key, why.to_string()))
        };
        let stale_timeout = timeout(
            "stale_timeout_s",
            self.stale_timeout_s.unwrap_or(DEFAULT_STALE_TIMEOUT_S),
        )?;
        let bus_loss_timeout = timeout(
            "bus_loss_timeout_s",
            self.bus_loss_timeout_s
                .unwrap_or(DEFAULT_BUS_LOSS_TIMEOUT_S),
        )?;
        if let Some(c) = &self.estop_channel {
            if c.trim().is_empty() {
                return Err(invalid("estop_channel", "must not be empty".into()));
            }
        }
        let last_resort = match self.last_resort_command {
            None => None,
            Some(argv) => {
                if argv.first().is_none_or(|p| p.trim().is_empty()) {
                    return Err(invalid(
                        "last_resort_command",
                        "must name a program: [\"program\", \"argument\", …]".into(),
                    ));
                }
                if argv.len() > MAX_LAST_RESORT_ARGS {
                    return Err(invalid(
                        "last_resort_command",
                        format!("{} arguments; at most {MAX_LAST_RESORT_ARGS}", argv.len()),
                    ));
                }
                Some(LastResort { argv })
            }
        };
        let stuck_after = match self.stuck_after_s {
            None => None,
            Some(v) => Some(timeout("stuck_after_s", v)?),
        };
        let t = self.thermal;
        let rated_current = match t.rated_current {
            Some(v) => v,
            None => nameplate
                .get("current_A")
                .and_then(|v| v.as_f64())
                .ok_or_else(|| {
                    invalid(
                        "thermal.rated_current_A",
                        "missing, and the nameplate has no current_A to take it from".into(),
                    )
                })?,
        };
        let rated_current = positive("thermal.rated_current_A", rated_current)?;
        let rated_rise = positive(
            "thermal.rated_rise_K",
            t.rated_rise.unwrap_or(DEFAULT_RATED_RISE_K),
        )?;
        let time_constant = positive(
            "thermal.time_constant_s",
            t.time_constant_s.unwrap_or(DEFAULT_THERMAL_TIME_CONSTANT_S),
        )?;
        let ambient = t.ambient.unwrap_or(DEFAULT_AMBIENT_C);
        if !(-50.0..=100.0).contains(&ambient) {
            return Err(invalid(
                "thermal.ambient_C",
                format!("{ambient} °C is not a plausible ambient (−50 to 100)"),
            ));
        }
        let max_winding = t.max_winding.unwrap_or(DEFAULT_MAX_WINDING_C);
        if !(max_winding.is_finite() && max_winding > ambient) {
            return Err(invalid(
                "thermal.max_winding_C",
                format!("{max_winding} °C must be above the ambient {ambient} °C"),
            ));
        }
        Ok(Supervision {
            max_power,
            stale_timeout,
            bus_loss_timeout,
            estop_channel: self.estop_channel,
            last_resort,
            stuck_after,
            thermal: ThermalModel {
                rated_current,
                rated_rise,
                time_constant,
                ambient,
                max_winding,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::config::Config;

    /// `config/sim-dc-daemon.toml` writes the defaults out: they must be
    /// the defaults.
    #[test]
    fn the_documented_defaults_are_the_defaults() {
        let written = Config::parse(
            "sim-dc-daemon.toml",
            include_str!("../../config/sim-dc-daemon.toml"),
        )
        .unwrap();
        let default = Config::embedded_default();
        assert_eq!(written.common.supervision, default.common.supervision);
        assert_eq!(written.common.retention, default.common.retention);
        assert_eq!(written.common.limits, default.common.limits);
        let rated = default.common.supervision.thermal.rated_current;
        assert_eq!(
            super::Supervision::defaults(&default.common.limits, rated),
            default.common.supervision
        );
    }
}
