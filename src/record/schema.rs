//! Names and JSON Schemas of the contract's MCAP layout.
//!
//! Every channel carries JSON messages (`message_encoding = "json"`) with a
//! JSON Schema (draft 2020-12, `encoding = "jsonschema"`). The schema texts
//! below are written into every record as they are; changing one is a new
//! `schema_version`.

/// Message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every schema.
pub const SCHEMA_ENCODING: &str = "jsonschema";

/// Name of the metadata record that describes the test.
pub const METADATA_NAME: &str = "motorbench.test";

/// Required keys of the `motorbench.test` metadata record.
pub const METADATA_KEYS: [&str; 6] = [
    "schema_version",
    "kind",
    "motor_id",
    "started_at",
    "nameplate",
    "config",
];

/// Key of the `motorbench.test` metadata that version 2 adds: the test
/// start as Unix time in ns (an integer, as text), the origin of
/// `log_time` (see [`super::TestStart`]).
pub const METADATA_START_TIME_NS: &str = "start_time_ns";

/// Name of the metadata record `motorbench recover` adds to the finished
/// copy of a cut record: what was cut (an additive extension).
pub const METADATA_RECOVERY: &str = "motorbench.recovery";

/// Key of `motorbench.recovery`: the messages read before the cut.
pub const RECOVERY_MESSAGES: &str = "messages";

/// Key of `motorbench.recovery`: the byte offset of the cut in the cut file.
pub const RECOVERY_OFFSET: &str = "damage_offset";

/// Key of `motorbench.recovery`: where the cut was and what the reader
/// found there, as [`super::Recovery`]'s reason.
pub const RECOVERY_REASON: &str = "reason";

/// Topic prefix of measured channels.
pub const SENSOR_PREFIX: &str = "/sensor/";
/// Topic prefix of commanded channels.
pub const COMMAND_PREFIX: &str = "/command/";

/// Topic of segment start/end markers.
pub const TOPIC_SEGMENT: &str = "/bench/segment";
/// Topic of induction-machine operating points.
pub const TOPIC_OPERATING_POINT: &str = "/bench/operating_point";
/// Topic of bench events.
pub const TOPIC_EVENT: &str = "/bench/event";
/// Topic of the identification (and diagnosis) report.
pub const TOPIC_RESULT: &str = "/bench/result";
/// Topic of the stretches where the supply could not follow its set
/// point (an additive extension of the contract).
pub const TOPIC_SUPPLY_LIMIT: &str = "/bench/supply_limit";
/// Topic of the induction machine's standard-test readings (an additive
/// extension of the contract).
pub const TOPIC_STANDARD_TEST: &str = "/bench/standard_test";

/// Schema of `/sensor/*` and `/command/*` messages.
pub const SCHEMA_SAMPLE: &str = "motorbench.Sample";
/// Schema of `/bench/segment` messages.
pub const SCHEMA_SEGMENT: &str = "motorbench.Segment";
/// Schema of `/bench/operating_point` messages.
pub const SCHEMA_OPERATING_POINT: &str = "motorbench.OperatingPoint";
/// Schema of `/bench/event` messages in version 1 records.
pub const SCHEMA_EVENT: &str = "motorbench.Event";
/// Schema of `/bench/event` messages in version 2 records: Foxglove's log
/// message, so that Foxglove's Log panel shows the events.
pub const SCHEMA_LOG: &str = "foxglove.Log";
/// Schema of `/bench/result` messages.
pub const SCHEMA_RESULT: &str = "motorbench.Result";
/// Schema of `/bench/supply_limit` messages.
pub const SCHEMA_SUPPLY_LIMIT: &str = "motorbench.SupplyLimit";
/// Schema of `/bench/standard_test` messages.
pub const SCHEMA_STANDARD_TEST: &str = "motorbench.StandardTest";

/// JSON Schema of `motorbench.Sample`: `{"value": number}`. (A non-finite
/// reading, which JSON cannot carry, is reported on `/bench/event`.)
pub const SAMPLE_JSON_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "motorbench.Sample",
  "description": "One reading of a /sensor/ or /command/ channel, in the channel's SI unit.",
  "type": "object",
  "properties": {
    "value": {"type": "number"}
  },
  "required": ["value"],
  "additionalProperties": false
}"#;

/// JSON Schema of `motorbench.Segment`.
pub const SEGMENT_JSON_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "motorbench.Segment",
  "description": "Start or end of a segment: one step, one coast-down or one sweep.",
  "type": "object",
  "properties": {
    "index": {"type": "integer", "minimum": 0},
    "kind": {"enum": ["dc_step", "dc_coastdown", "im_slip_sweep", "im_dc_resistance", "im_no_load", "im_locked_rotor"]},
    "phase": {"enum": ["start", "end"]},
    "label": {"type": "string"}
  },
  "required": ["index", "kind", "phase", "label"],
  "additionalProperties": false
}"#;

/// JSON Schema of `motorbench.OperatingPoint`.
pub const OPERATING_POINT_JSON_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "motorbench.OperatingPoint",
  "description": "One steady-state operating point of an induction-machine slip sweep (SI units; slip is a fraction).",
  "type": "object",
  "properties": {
    "segment": {"type": "integer", "minimum": 0},
    "slip": {"type": "number"},
    "line_voltage": {"type": "number"},
    "line_current": {"type": "number"},
    "input_power": {"type": "number"},
    "speed": {"type": "number"},
    "frequency": {"type": "number"},
    "torque": {"type": ["number", "null"]},
    "winding_temperature": {"type": "number", "description": "degC: the winding thermometer's mean over the point's averaging window; absent where the rig has no thermometer"}
  },
  "required": ["segment", "slip", "line_voltage", "line_current", "input_power", "speed", "frequency", "torque"],
  "additionalProperties": false
}"#;

/// JSON Schema of `foxglove.Log` as version 2 writes it on `/bench/event`
/// (Foxglove's fields; see [`super::log_event`] for the level numbers).
pub const LOG_JSON_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "foxglove.Log",
  "description": "Something the bench did or saw, for a person (Foxglove's log message).",
  "type": "object",
  "properties": {
    "timestamp": {
      "type": "object",
      "description": "Wall-clock time of the event (equal to the message's log_time).",
      "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}
      },
      "required": ["sec", "nsec"]
    },
    "level": {
      "description": "Foxglove log level: 2 INFO (info), 3 WARNING (warn), 4 ERROR (abort: the test was stopped and the rig put in its safe state).",
      "enum": [0, 1, 2, 3, 4, 5]
    },
    "message": {"type": "string"},
    "name": {"type": "string", "description": "Always motorbench."},
    "file": {"type": "string"},
    "line": {"type": "integer", "minimum": 0}
  },
  "required": ["timestamp", "level", "message", "name", "file", "line"]
}"#;

/// JSON Schema of `motorbench.Event` (version 1; read, no longer written).
pub const EVENT_JSON_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "motorbench.Event",
  "description": "Something the bench did or saw, for a person.",
  "type": "object",
  "properties": {
    "level": {"enum": ["info", "warn", "abort"]},
    "message": {"type": "string"}
  },
  "required": ["level", "message"],
  "additionalProperties": false
}"#;

/// JSON Schema of `motorbench.Result`: the report as the CLI's `--json`
/// prints it, a JSON object.
pub const RESULT_JSON_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "motorbench.Result",
  "description": "The identification (and diagnosis) report, as printed by the CLI's --json.",
  "type": "object"
}"#;

/// JSON Schema of `motorbench.SupplyLimit`. Readers ignore keys they do
/// not know, so keys may be added.
pub const SUPPLY_LIMIT_JSON_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "motorbench.SupplyLimit",
  "description": "A stretch of a segment where the supply did not follow its set point: it held its current limit (current_limit) or did not reach the commanded voltage (voltage_compliance). Times in s since the start of the test.",
  "type": "object",
  "properties": {
    "segment": {"type": "integer", "minimum": 0},
    "kind": {"enum": ["current_limit", "voltage_compliance"]},
    "from": {"type": "number"},
    "to": {"type": "number"},
    "commanded_voltage": {"type": "number"},
    "measured_voltage": {"type": "number"},
    "current_limit": {"type": ["number", "null"]},
    "peak_current": {"type": "number"}
  },
  "required": ["segment", "kind", "from", "to", "commanded_voltage", "measured_voltage", "current_limit", "peak_current"]
}"#;

/// JSON Schema of `motorbench.StandardTest`: one averaged reading of an
/// induction machine's standard test, its test named by `test` (the
/// segment kind). Readers ignore keys they do not know.
pub const STANDARD_TEST_JSON_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "motorbench.StandardTest",
  "description": "One averaged reading of an induction machine's standard test (SI units; winding temperature in degrees Celsius): a DC winding-resistance reading between two line terminals (test im_dc_resistance), or a no-load (im_no_load) or locked-rotor (im_locked_rotor) reading on the AC supply.",
  "type": "object",
  "properties": {
    "test": {"enum": ["im_dc_resistance", "im_no_load", "im_locked_rotor"]},
    "segment": {"type": "integer", "minimum": 0},
    "dc_voltage": {"type": "number"},
    "dc_current": {"type": "number"},
    "line_voltage": {"type": "number"},
    "line_current": {"type": "number"},
    "input_power": {"type": "number"},
    "frequency": {"type": "number"},
    "winding_temperature": {"type": ["number", "null"]}
  },
  "required": ["test", "segment", "winding_temperature"]
}"#;

/// The `/bench/*` topics with their schema names and schema texts, in the
/// order the recorder declares them (version 2).
pub const BENCH_TOPICS: [(&str, &str, &str); 6] = [
    (TOPIC_SEGMENT, SCHEMA_SEGMENT, SEGMENT_JSON_SCHEMA),
    (
        TOPIC_OPERATING_POINT,
        SCHEMA_OPERATING_POINT,
        OPERATING_POINT_JSON_SCHEMA,
    ),
    (TOPIC_EVENT, SCHEMA_LOG, LOG_JSON_SCHEMA),
    (TOPIC_RESULT, SCHEMA_RESULT, RESULT_JSON_SCHEMA),
    (
        TOPIC_SUPPLY_LIMIT,
        SCHEMA_SUPPLY_LIMIT,
        SUPPLY_LIMIT_JSON_SCHEMA,
    ),
    (
        TOPIC_STANDARD_TEST,
        SCHEMA_STANDARD_TEST,
        STANDARD_TEST_JSON_SCHEMA,
    ),
];

/// Whether `topic` is the contract's topic for a sample channel of
/// `quantity`: `/sensor/<quantity>` or `/command/<quantity>`.
pub fn is_sample_topic_for(topic: &str, quantity: &str) -> bool {
    !quantity.is_empty()
        && [SENSOR_PREFIX, COMMAND_PREFIX]
            .iter()
            .any(|p| topic.strip_prefix(p) == Some(quantity))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schemas_are_json_objects_of_draft_2020_12() {
        let all = [
            (SCHEMA_SAMPLE, SAMPLE_JSON_SCHEMA),
            (SCHEMA_SEGMENT, SEGMENT_JSON_SCHEMA),
            (SCHEMA_OPERATING_POINT, OPERATING_POINT_JSON_SCHEMA),
            (SCHEMA_EVENT, EVENT_JSON_SCHEMA),
            (SCHEMA_LOG, LOG_JSON_SCHEMA),
            (SCHEMA_RESULT, RESULT_JSON_SCHEMA),
            (SCHEMA_SUPPLY_LIMIT, SUPPLY_LIMIT_JSON_SCHEMA),
            (SCHEMA_STANDARD_TEST, STANDARD_TEST_JSON_SCHEMA),
        ];
        for (name, text) in all {
            let v: serde_json::Value = serde_json::from_str(text).unwrap();
            assert_eq!(
                v["$schema"], "https://json-schema.org/draft/2020-12/schema",
                "{name}"
            );
            assert_eq!(v["title"], name);
            assert_eq!(v["type"], "object");
        }
    }

    #[test]
    fn segment_schema_matches_the_contract() {
        let v: serde_json::Value = serde_json::from_str(SEGMENT_JSON_SCHEMA).unwrap();
        assert_eq!(
            v["properties"]["kind"]["enum"],
            serde_json::json!([
                "dc_step",
                "dc_coastdown",
                "im_slip_sweep",
                "im_dc_resistance",
                "im_no_load",
                "im_locked_rotor"
            ])
        );
        assert_eq!(
            v["properties"]["phase"]["enum"],
            serde_json::json!(["start", "end"])
        );
        let v: serde_json::Value = serde_json::from_str(EVENT_JSON_SCHEMA).unwrap();
        assert_eq!(
            v["properties"]["level"]["enum"],
            serde_json::json!(["info", "warn", "abort"])
        );
        let v: serde_json::Value = serde_json::from_str(OPERATING_POINT_JSON_SCHEMA).unwrap();
        assert_eq!(v["required"].as_array().unwrap().len(), 8);
    }

    #[test]
    fn sample_topics() {
        assert!(is_sample_topic_for("/sensor/speed", "speed"));
        assert!(is_sample_topic_for("/command/dyno_speed", "dyno_speed"));
        assert!(!is_sample_topic_for("/sensor/speed", "torque"));
        assert!(!is_sample_topic_for("/bench/speed", "speed"));
        assert!(!is_sample_topic_for("/sensor/", ""));
    }
}
