//! The `[[fault]]` array of a test configuration: faults injected into
//! the rig on purpose, to show what the bench does about each (the fault
//! matrix of `docs/reliability.md`). Each entry names a `kind`, when it
//! starts (`at_s`, test time), how long it lasts (`for_s`, optional:
//! to the end of the test), what it acts on (`target`: a sensor channel's
//! quantity, or a device's role, where the kind needs one) and a `value`
//! where the kind takes one. Unknown kinds and keys are refused with the
//! key (`fault[2].kind`) named, as everywhere in the configuration.
//!
//! A configuration without `[[fault]]` injects nothing: the wrappers in
//! [`crate::rig::fault`] are not even put in place.

use serde::Deserialize;

use super::{invalid, ConfigError};
use crate::excerpt::quoted;

/// One raw `[[fault]]` entry.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFault {
    kind: String,
    at_s: f64,
    for_s: Option<f64>,
    target: Option<String>,
    value: Option<f64>,
}

/// What a fault does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// A sensor channel (`target`) holds one value: `value`, or its
    /// latest reading before the fault.
    Stuck,
    /// A sensor channel's readings are offset by `value` (one reading, or
    /// for `for_s`).
    Spike,
    /// A sensor channel reads NaN.
    Nan,
    /// A sensor channel reads +∞ (−∞ when `value` is negative).
    Inf,
    /// The sample timestamps jump by `value` seconds (negative: back).
    ClockJump,
    /// The encoder count loses the fraction `value` (default 1: all) of
    /// its counts while the fault lasts.
    EncoderLosesCounts,
    /// The supply limits its current at `value` A (from its next command
    /// on).
    CurrentLimit,
    /// The power stage (`target`, default every stage) answers the safe
    /// command but does not act on it.
    IgnoreSafeState,
    /// The power stage ignores the safe command and the output disable.
    IgnoreDisable,
    /// A served device (`target`) does not answer.
    BusTimeout,
    /// A served device (`target`) answers with the Modbus exception code
    /// `value` (default 4, server device failure).
    ModbusException,
    /// A served device's link (`target`) goes away for good.
    Disconnect,
    /// A served RTU device's replies (`target`) carry a wrong CRC.
    CrcError,
    /// Garbage bytes on a served RTU device's line (`target`) before each
    /// reply.
    Garbage,
}

impl FaultKind {
    /// Every kind, with its name in `kind`.
    pub const ALL: [(FaultKind, &'static str); 14] = [
        (FaultKind::Stuck, "stuck"),
        (FaultKind::Spike, "spike"),
        (FaultKind::Nan, "nan"),
        (FaultKind::Inf, "inf"),
        (FaultKind::ClockJump, "clock_jump"),
        (FaultKind::EncoderLosesCounts, "encoder_loses_counts"),
        (FaultKind::CurrentLimit, "current_limit"),
        (FaultKind::IgnoreSafeState, "ignore_safe_state"),
        (FaultKind::IgnoreDisable, "ignore_disable"),
        (FaultKind::BusTimeout, "bus_timeout"),
        (FaultKind::ModbusException, "modbus_exception"),
        (FaultKind::Disconnect, "disconnect"),
        (FaultKind::CrcError, "crc_error"),
        (FaultKind::Garbage, "garbage"),
    ];

    /// The name in `kind`.
    pub fn name(self) -> &'static str {
        FaultKind::ALL
            .iter()
            .find(|(k, _)| *k == self)
            .map_or("?", |(_, n)| n)
    }

    fn parse(name: &str) -> Option<FaultKind> {
        FaultKind::ALL
            .iter()
            .find(|(_, n)| *n == name)
            .map(|(k, _)| *k)
    }

    /// Acts on a sensor channel's readings.
    pub fn on_sensors(self) -> bool {
        matches!(
            self,
            FaultKind::Stuck
                | FaultKind::Spike
                | FaultKind::Nan
                | FaultKind::Inf
                | FaultKind::ClockJump
                | FaultKind::EncoderLosesCounts
        )
    }

    /// Acts on a power stage.
    pub fn on_stage(self) -> bool {
        matches!(
            self,
            FaultKind::CurrentLimit | FaultKind::IgnoreSafeState | FaultKind::IgnoreDisable
        )
    }

    /// Acts on a served device's protocol (a protocol-served rig only).
    pub fn on_protocol(self) -> bool {
        matches!(
            self,
            FaultKind::BusTimeout
                | FaultKind::ModbusException
                | FaultKind::Disconnect
                | FaultKind::CrcError
                | FaultKind::Garbage
        )
    }

    /// Only on an RTU line.
    pub fn rtu_only(self) -> bool {
        matches!(self, FaultKind::CrcError | FaultKind::Garbage)
    }

    /// `target` is required.
    fn needs_target(self) -> bool {
        matches!(
            self,
            FaultKind::Stuck | FaultKind::Spike | FaultKind::Nan | FaultKind::Inf
        ) || self.on_protocol()
    }

    /// `value` is required.
    fn needs_value(self) -> bool {
        matches!(
            self,
            FaultKind::Spike | FaultKind::ClockJump | FaultKind::CurrentLimit
        )
    }

    /// `value` means something.
    fn takes_value(self) -> bool {
        self.needs_value()
            || matches!(
                self,
                FaultKind::Stuck
                    | FaultKind::Inf
                    | FaultKind::EncoderLosesCounts
                    | FaultKind::ModbusException
            )
    }

    /// `target` means something.
    fn takes_target(self) -> bool {
        self.needs_target() || matches!(self, FaultKind::IgnoreSafeState | FaultKind::IgnoreDisable)
    }
}

/// One validated fault. See the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct Fault {
    /// Its index in `[[fault]]` (for messages: `fault[i]`).
    pub index: usize,
    /// What it does.
    pub kind: FaultKind,
    /// When it starts, s of test time.
    pub at_s: f64,
    /// How long it lasts, s; `None`: to the end of the test (a spike
    /// without it lasts one reading).
    pub for_s: Option<f64>,
    /// The channel's quantity or the device's role it acts on.
    pub target: Option<String>,
    /// The kind's value.
    pub value: Option<f64>,
}

impl Fault {
    /// Whether the fault acts at test time `t_s`.
    pub fn active(&self, t_s: f64) -> bool {
        t_s >= self.at_s && self.for_s.is_none_or(|d| t_s < self.at_s + d)
    }

    /// Its key prefix in messages: `fault[i]`.
    pub fn key(&self) -> String {
        format!("fault[{}]", self.index)
    }

    /// One line for a person and the record.
    pub fn describe(&self) -> String {
        let mut s = format!("{} {} at {} s", self.key(), self.kind.name(), self.at_s);
        if let Some(d) = self.for_s {
            s.push_str(&format!(" for {d} s"));
        }
        if let Some(t) = &self.target {
            s.push_str(&format!(" on {t}"));
        }
        if let Some(v) = self.value {
            s.push_str(&format!(" (value {v})"));
        }
        s
    }
}

/// The validated `[[fault]]` array; empty when the file has none.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FaultPlan {
    /// The faults, in file order.
    pub faults: Vec<Fault>,
}

impl FaultPlan {
    /// No fault at all.
    pub fn is_empty(&self) -> bool {
        self.faults.is_empty()
    }

    /// The faults acting on sensor readings.
    pub fn sensor_faults(&self) -> Vec<Fault> {
        self.of(FaultKind::on_sensors)
    }

    /// The faults acting on power stages.
    pub fn stage_faults(&self) -> Vec<Fault> {
        self.of(FaultKind::on_stage)
    }

    /// The faults acting on served devices' protocols.
    pub fn protocol_faults(&self) -> Vec<Fault> {
        self.of(FaultKind::on_protocol)
    }

    fn of(&self, which: impl Fn(FaultKind) -> bool) -> Vec<Fault> {
        self.faults
            .iter()
            .filter(|f| which(f.kind))
            .cloned()
            .collect()
    }
}

/// What the rig offers the faults, for their validation.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FaultRig<'a> {
    /// The devices a protocol fault may name (empty: the rig is not
    /// served behind a protocol).
    pub served: &'a [&'a str],
    /// The served devices are on RTU lines.
    pub rtu: bool,
    /// The served devices that stream records on a serial line instead of
    /// answering Modbus requests (a streaming DAQ): they have a line
    /// whatever the transport, and no exception replies.
    pub streams: &'a [&'a str],
    /// The served devices on a CAN bus behind an SLCAN adapter (also in
    /// `streams`): no Modbus, and no frame with a bad CRC ever reaches
    /// the host (the CAN controllers retransmit it).
    pub can: &'a [&'a str],
    /// The stages a stage fault may name.
    pub stages: &'a [&'a str],
    /// The stage that feeds the machine takes a current limit.
    pub current_limit: bool,
}

/// Why a fault of `kind` may not be written with its `field` `given` or
/// not, where the kind `(takes, needs)` one: missing where it needs one,
/// given where it takes none.
fn presence_error(
    kind: FaultKind,
    field: &str,
    given: bool,
    (takes, needs): (bool, bool),
) -> Option<String> {
    match (given, takes, needs) {
        (false, _, true) => Some(format!("missing: a {} fault needs one", kind.name())),
        (true, false, _) => Some(format!("a {} fault takes no {field}", kind.name())),
        _ => None,
    }
}

/// Why the target `t` is none of `names` (the `what`s the rig `offers`,
/// e.g. "has"), the rig's names listed.
fn unknown_target(t: &str, names: &[&str], what: &str, offers: &str) -> Option<String> {
    (!names.contains(&t)).then(|| {
        format!(
            "no {what} {} (this rig {offers}: {})",
            quoted(t),
            names.join(", ")
        )
    })
}

/// Validate `raw` (from `source`) for a rig offering `rig`.
pub(crate) fn validate_faults(
    source: &str,
    raw: Vec<RawFault>,
    rig: FaultRig<'_>,
) -> Result<FaultPlan, ConfigError> {
    if raw.len() > MAX_FAULTS {
        return Err(invalid(
            source,
            "fault",
            format!("{} faults; at most {MAX_FAULTS}", raw.len()),
        ));
    }
    let mut faults = Vec::with_capacity(raw.len());
    for (index, r) in raw.into_iter().enumerate() {
        let key = |k: &str| format!("fault[{index}].{k}");
        let bad = |k: &str, why: String| invalid(source, &key(k), why);
        let kind = FaultKind::parse(&r.kind).ok_or_else(|| {
            bad(
                "kind",
                format!(
                    "unknown fault {} (this version has: {})",
                    quoted(&r.kind),
                    FaultKind::ALL.map(|(_, n)| format!("\"{n}\"")).join(", ")
                ),
            )
        })?;
        if !(r.at_s.is_finite() && r.at_s >= 0.0 && r.at_s <= MAX_TIME_S) {
            return Err(bad(
                "at_s",
                format!("{} must be 0 to {MAX_TIME_S} s", r.at_s),
            ));
        }
        if let Some(d) = r.for_s {
            if !(d.is_finite() && d > 0.0 && d <= MAX_TIME_S) {
                return Err(bad(
                    "for_s",
                    format!("{d} must be > 0 and ≤ {MAX_TIME_S} s"),
                ));
            }
            if kind == FaultKind::ClockJump || kind == FaultKind::Disconnect {
                return Err(bad(
                    "for_s",
                    format!("a {} is a step: it takes no duration", kind.name()),
                ));
            }
        }
        let target = (kind.takes_target(), kind.needs_target());
        if let Some(why) = presence_error(kind, "target", r.target.is_some(), target) {
            return Err(bad("target", why));
        }
        if r.target.as_ref().is_some_and(|t| t.trim().is_empty()) {
            return Err(bad("target", "must not be empty".into()));
        }
        let value = (kind.takes_value(), kind.needs_value());
        if let Some(why) = presence_error(kind, "value", r.value.is_some(), value) {
            return Err(bad("value", why));
        }
        if let Some(v) = r.value.filter(|v| !v.is_finite()) {
            return Err(bad("value", format!("{v} must be finite")));
        }
        let value_check = match (kind, r.value) {
            (FaultKind::CurrentLimit, Some(v)) if v <= 0.0 => Some(format!("{v} A must be > 0")),
            (FaultKind::EncoderLosesCounts, Some(v)) if !(v > 0.0 && v <= 1.0) => {
                Some(format!("{v} must be a fraction of the counts, > 0 and ≤ 1"))
            }
            (FaultKind::ModbusException, Some(v))
                if !(1.0..=255.0).contains(&v) || v.fract() != 0.0 =>
            {
                Some(format!("{v} is not a Modbus exception code (1 to 255)"))
            }
            (FaultKind::ClockJump, Some(0.0)) => Some("a jump of 0 s is no jump".into()),
            _ => None,
        };
        if let Some(why) = value_check {
            return Err(bad("value", why));
        }
        if kind.on_protocol() {
            if rig.served.is_empty() {
                return Err(bad(
                    "kind",
                    format!(
                        "a {} fault needs a rig served behind its protocol (rig.modbus.simulate)",
                        kind.name()
                    ),
                ));
            }
            let t = r.target.as_deref().unwrap_or_default();
            let streams = rig.streams.contains(&t);
            if kind.rtu_only() && !rig.rtu && !streams {
                return Err(bad(
                    "kind",
                    format!(
                        "a {} fault needs the rig served over RTU, or a streaming serial DAQ as its target",
                        kind.name()
                    ),
                ));
            }
            if let Some(why) = unknown_target(t, rig.served, "served device", "serves") {
                return Err(bad("target", why));
            }
            if kind == FaultKind::CrcError && rig.can.contains(&t) {
                return Err(bad(
                    "kind",
                    format!(
                        "{} is on a CAN bus, whose controllers retransmit a frame that fails its CRC by themselves: no bad frame reaches the bench (lose frames with bus_timeout, corrupt the adapter's line with garbage)",
                        quoted(t)
                    ),
                ));
            }
            if kind == FaultKind::ModbusException && streams {
                return Err(bad(
                    "kind",
                    format!(
                        "{} streams records on a serial line: it answers no Modbus request, so it has no exception to reply with",
                        quoted(t)
                    ),
                ));
            }
        }
        if kind == FaultKind::CurrentLimit && !rig.current_limit {
            return Err(bad(
                "kind",
                "a current_limit fault needs a supply that takes a current limit (a DC rig's)"
                    .into(),
            ));
        }
        if kind.on_stage() {
            if let Some(t) = r.target.as_deref() {
                if let Some(why) = unknown_target(t, rig.stages, "stage", "has") {
                    return Err(bad("target", why));
                }
            }
        }
        faults.push(Fault {
            index,
            kind,
            at_s: r.at_s,
            for_s: r.for_s,
            target: r.target,
            value: r.value,
        });
    }
    Ok(FaultPlan { faults })
}

/// The most faults one test may inject.
pub const MAX_FAULTS: usize = 64;
/// The latest time a fault may start or the longest it may last, s.
pub const MAX_TIME_S: f64 = 86_400.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(text: &str) -> Vec<RawFault> {
        #[derive(Deserialize)]
        struct Doc {
            fault: Vec<RawFault>,
        }
        toml::from_str::<Doc>(text).unwrap().fault
    }

    const DC: FaultRig<'static> = FaultRig {
        served: &[],
        rtu: false,
        streams: &[],
        can: &[],
        stages: &["power_stage"],
        current_limit: true,
    };

    #[test]
    fn a_fault_plan_validates_and_says_when_each_acts() {
        let plan = validate_faults(
            "t.toml",
            raw("[[fault]]\nkind = \"stuck\"\nat_s = 1.0\nfor_s = 0.5\ntarget = \"armature_current\"\n\
                 [[fault]]\nkind = \"ignore_safe_state\"\nat_s = 0\n"),
            DC,
        )
        .unwrap();
        assert_eq!(plan.sensor_faults().len(), 1);
        assert_eq!(plan.stage_faults().len(), 1);
        let f = &plan.faults[0];
        assert!(!f.active(0.99) && f.active(1.0) && f.active(1.49) && !f.active(1.5));
        assert!(plan.faults[1].active(1e6));
        assert_eq!(
            f.describe(),
            "fault[0] stuck at 1 s for 0.5 s on armature_current"
        );
    }

    #[test]
    fn bad_faults_name_their_key() {
        let tcp = FaultRig {
            served: &["power_stage", "sensors"],
            rtu: false,
            streams: &[],
            can: &[],
            stages: &["power_stage"],
            current_limit: true,
        };
        // A streaming DAQ has a line over TCP too, but no exception reply.
        let streaming = FaultRig {
            streams: &["sensors"],
            ..tcp
        };
        // A CAN encoder behind an SLCAN adapter: its line takes garbage,
        // but no bad CRC reaches the bench, and it answers no Modbus.
        let can = FaultRig {
            served: &["power_stage", "sensors", "encoder"],
            streams: &["encoder"],
            can: &["encoder"],
            ..tcp
        };
        // What follows `[[fault]]`, the rig, and what the refusal says.
        let refused = [
            (
                "kind = \"gremlins\"\nat_s = 1\n",
                DC,
                "fault[0].kind: unknown fault \"gremlins\"",
            ),
            ("kind = \"nan\"\nat_s = 1\n", DC, "fault[0].target: missing"),
            (
                "kind = \"spike\"\nat_s = 1\ntarget = \"x\"\n",
                DC,
                "fault[0].value: missing",
            ),
            (
                "kind = \"nan\"\nat_s = -1\ntarget = \"x\"\n",
                DC,
                "fault[0].at_s",
            ),
            (
                "kind = \"clock_jump\"\nat_s = 1\nvalue = 1\nfor_s = 2\n",
                DC,
                "fault[0].for_s",
            ),
            (
                "kind = \"bus_timeout\"\nat_s = 1\nfor_s = 1\ntarget = \"power_stage\"\n",
                DC,
                "needs a rig served behind its protocol",
            ),
            (
                "kind = \"crc_error\"\nat_s = 1\ntarget = \"sensors\"\n",
                tcp,
                "needs the rig served over RTU",
            ),
            (
                "kind = \"garbage\"\nat_s = 1\ntarget = \"power_stage\"\n",
                streaming,
                "needs the rig served over RTU",
            ),
            (
                "kind = \"modbus_exception\"\nat_s = 1\ntarget = \"sensors\"\n",
                streaming,
                "fault[0].kind: \"sensors\" streams records on a serial line",
            ),
            (
                "kind = \"disconnect\"\nat_s = 1\ntarget = \"daq\"\n",
                tcp,
                "fault[0].target: no served device \"daq\"",
            ),
            (
                "kind = \"crc_error\"\nat_s = 1\ntarget = \"encoder\"\n",
                can,
                "fault[0].kind: \"encoder\" is on a CAN bus",
            ),
            (
                "kind = \"modbus_exception\"\nat_s = 1\nvalue = 6\ntarget = \"encoder\"\n",
                can,
                "fault[0].kind: \"encoder\" streams records",
            ),
            (
                "kind = \"ignore_disable\"\nat_s = 1\ntarget = \"supply\"\n",
                DC,
                "fault[0].target: no stage \"supply\"",
            ),
            (
                "kind = \"encoder_loses_counts\"\nat_s = 1\nvalue = 2\n",
                DC,
                "fault[0].value",
            ),
        ];
        for (fault, rig, says) in refused {
            let e =
                validate_faults("t.toml", raw(&format!("[[fault]]\n{fault}")), rig).unwrap_err();
            let e = e.to_string();
            assert!(
                e.starts_with("t.toml: fault[0].") && e.contains(says),
                "{fault}: {e}"
            );
        }
        // The line faults a rig's devices do take.
        let accepted = [
            (
                "kind = \"crc_error\"\nat_s = 1\ntarget = \"sensors\"\n\
                 [[fault]]\nkind = \"garbage\"\nat_s = 1\ntarget = \"sensors\"\n",
                streaming,
            ),
            (
                "kind = \"garbage\"\nat_s = 1\ntarget = \"encoder\"\n\
                 [[fault]]\nkind = \"bus_timeout\"\nat_s = 1\ntarget = \"encoder\"\n",
                can,
            ),
        ];
        for (faults, rig) in accepted {
            let plan = validate_faults("t.toml", raw(&format!("[[fault]]\n{faults}")), rig);
            assert_eq!(plan.unwrap().protocol_faults().len(), 2, "{faults}");
        }
        // Unknown keys are refused by the parser (with their line).
        let text = "[[fault]]\nkind = \"nan\"\nat_s = 1\nwhen = 2\n";
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct Doc {
            fault: Vec<RawFault>,
        }
        assert!(toml::from_str::<Doc>(text).is_err());
    }
}
