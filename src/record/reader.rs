//! Reads a motorbench MCAP file back into entries and a [`Record`].
//!
//! The file is read in one linear pass over its records (chunks are
//! decompressed on the way, see [`super::mcap_walk`]: every length is
//! bounded by the file's size, every chunk's CRC is checked before its
//! records are used), so a damaged file, e.g. cut by a killed process or
//! with a flipped bit, still yields everything before the damage: the
//! damage is taken as the end of the data and reported, with its byte
//! offset, in [`Record::recovery`]. No index or summary is needed. A
//! copy finished by `motorbench recover` ([`super::recover_record`])
//! carries the cut file's damage in its `motorbench.recovery` metadata,
//! and reads back with the same [`Record::recovery`].
//!
//! The file is read from disk in pieces, a record (a chunk) at a time,
//! and [`read_record`] (so [`read_mcap`]) hands each entry to the
//! [`RecordBuilder`] as it is decoded: no list of entries is made, so
//! replaying a one-hour record takes no more memory than a short one.
//! [`read_entries`] collects them all (export, the records index).
//! Entries read before the `motorbench.test` metadata (which gives their
//! origin; motorbench writes it first, the contract does not say where)
//! wait for it.
//!
//! Refused as damaged ([`RecordError::Damaged`], naming the offset): a
//! file damaged before its MCAP header or its `motorbench.test` metadata,
//! and (by [`read_mcap`]) one with not a single message before the damage.
//!
//! Both contract versions read: in version 1 `log_time` is the time since
//! the start of the test; in version 2 it is wall-clock Unix time and the
//! metadata's `start_time_ns` is subtracted, so the entries (and all that
//! is computed from them) are the same whichever version wrote the file.
//! Events are read in either shape ([`super::log_event`]).
//!
//! Refused: files without the `motorbench.test` metadata record, with a
//! `schema_version` this build does not read ([`READ_SCHEMA_VERSIONS`]),
//! a version 2 file without a `start_time_ns` or with a message before
//! it, with a missing metadata
//! key, a sample channel without its `unit`/`quantity`/`source` metadata,
//! a channel not encoded as JSON, or a message that does not decode (the
//! error names the file, the topic and the log time).
//!
//! Consecutive sample messages with one log time are grouped into one
//! [`Entry::Samples`].
//! `/bench/operating_point` messages become [`Entry::OperatingPoint`] (a
//! message that does not decode as `motorbench.OperatingPoint` is refused).
//! Topics outside the contract are ignored.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use mcap::records::Record as McapRecord;
use serde::Deserialize;

use super::builder::RecordBuilder;
use super::error::{DecodeError, RecordError};
use super::im_tests::{implausible_temperature, StandardTestReading};
use super::log_event::AnyEvent;
use super::mcap_walk::{walk_source, Damage};
use super::schema::{
    is_sample_topic_for, COMMAND_PREFIX, MESSAGE_ENCODING, METADATA_NAME, METADATA_RECOVERY,
    METADATA_START_TIME_NS, RECOVERY_MESSAGES, RECOVERY_OFFSET, RECOVERY_REASON, SENSOR_PREFIX,
    TOPIC_EVENT, TOPIC_OPERATING_POINT, TOPIC_RESULT, TOPIC_SEGMENT, TOPIC_STANDARD_TEST,
    TOPIC_SUPPLY_LIMIT,
};
use super::thinning::Resolution;
use super::types::{ChannelSpec, Entry, OperatingPoint, Record, Recovery, SegmentKind, TestMeta};
use crate::contract::READ_SCHEMA_VERSIONS;

/// Everything [`read_entries`] finds in a file: the metadata, the sample
/// channels (in the order their channel records appear; [`Entry::Samples`]
/// indexes into this list), the entries in file order, and what was lost
/// if the file is damaged.
pub type Entries = (TestMeta, Vec<ChannelSpec>, Vec<Entry>, Option<Recovery>);

/// Where the messages of one channel go.
#[derive(Debug, Clone, Copy)]
enum Route {
    Sample(usize),
    Segment,
    OperatingPoint,
    Event,
    Result,
    SupplyLimit,
    StandardTest,
    Ignore,
}

#[derive(Deserialize)]
struct SamplePayload {
    value: f64,
}

/// Reads a record file into a [`Record`] (through [`RecordBuilder`], like
/// the live bench) at [`Resolution::Analysis`]: see [`read_record`].
pub fn read_mcap(path: &Path) -> Result<Record, RecordError> {
    read_record(path, Resolution::Analysis)
}

/// Reads a record file into a [`Record`] at `resolution`, handing each
/// entry to a [`RecordBuilder`] as it is read: the file is read in pieces
/// and no list of its entries is made, so at [`Resolution::Analysis`] the
/// memory a replay takes does not grow with the test's length.
///
/// A damaged file with not one message before the damage is refused
/// ([`RecordError::Damaged`]): there is nothing to identify.
pub fn read_record(path: &Path, resolution: Resolution) -> Result<Record, RecordError> {
    let mut builder = RecordBuilder::new(None, Vec::new()).resolution(resolution);
    let (meta, _, recovery) = read_into(path, &mut builder)?;
    refuse_if_empty(path, recovery.as_ref())?;
    builder.set_meta(meta);
    let mut record = builder.finish();
    record.recovery = recovery;
    Ok(record)
}

/// Refuses a damaged file with not one message before the damage
/// ([`RecordError::Damaged`]): there is nothing to identify or export.
pub fn refuse_if_empty(path: &Path, recovery: Option<&Recovery>) -> Result<(), RecordError> {
    match recovery.filter(|r| r.messages == 0) {
        Some(r) => Err(RecordError::Damaged {
            path: path.to_path_buf(),
            offset: r.offset,
            reason: format!("{}; not one message before the damage", r.reason),
        }),
        None => Ok(()),
    }
}

/// The [`Record`] of what [`read_entries`] read (through
/// [`RecordBuilder`], like the live bench) at `resolution`; its
/// `recovery` is not set.
pub fn build_record(
    meta: TestMeta,
    channels: Vec<ChannelSpec>,
    entries: &[Entry],
    resolution: Resolution,
) -> Record {
    let mut builder = RecordBuilder::new(Some(meta), channels).resolution(resolution);
    for e in entries {
        builder.push(e);
    }
    builder.finish()
}

/// Reads a record file into its metadata, sample channels and entries
/// (all of them, in memory). See the module docs for what is refused.
pub fn read_entries(path: &Path) -> Result<Entries, RecordError> {
    let mut entries = Vec::new();
    let (meta, channels, recovery) = read_into(path, &mut entries)?;
    Ok((meta, channels, entries, recovery))
}

/// A record file without its samples: what [`read_outline`] finds.
#[derive(Debug, Clone, PartialEq)]
pub struct Outline {
    /// The test's metadata.
    pub meta: TestMeta,
    /// The sample channels (the list [`Entry::Samples`] indexes into).
    pub channels: Vec<ChannelSpec>,
    /// Every entry but the samples, in file order.
    pub entries: Vec<Entry>,
    /// The sample values read.
    pub samples: u64,
    /// The latest time of any entry, samples included, ns since the start.
    pub last_t_ns: u64,
    /// What was lost if the file is damaged.
    pub recovery: Option<Recovery>,
}

/// [`Outline`]'s entries and counts as they are read.
#[derive(Default)]
struct OutlineSink {
    entries: Vec<Entry>,
    samples: u64,
    last_t_ns: u64,
}

impl EntrySink for OutlineSink {
    fn channel(&mut self, _: &ChannelSpec) {}

    fn entry(&mut self, entry: Entry) {
        self.last_t_ns = self.last_t_ns.max(entry.t_ns());
        match entry {
            Entry::Samples { values, .. } => self.samples += values.len() as u64,
            other => self.entries.push(other),
        }
    }
}

/// Reads a record file's metadata, events, markers and result, counting
/// its samples without keeping them: how a record ended, in memory that
/// does not grow with its length (the daemon's records index reads every
/// interrupted record at start-up). Refused as [`read_entries`] refuses.
pub fn read_outline(path: &Path) -> Result<Outline, RecordError> {
    let mut sink = OutlineSink::default();
    let (meta, channels, recovery) = read_into(path, &mut sink)?;
    Ok(Outline {
        meta,
        channels,
        entries: sink.entries,
        samples: sink.samples,
        last_t_ns: sink.last_t_ns,
        recovery,
    })
}

/// Reads a record file, handing each entry to `each` as it is read (in
/// file order, its time from the test's start), without keeping any: for
/// work that streams a record (the export). Its metadata, sample channels
/// (the list [`Entry::Samples`] indexes into) and what was lost if it is
/// damaged. Refused as [`read_entries`] refuses.
pub fn read_each(
    path: &Path,
    each: &mut dyn FnMut(Entry),
) -> Result<(TestMeta, Vec<ChannelSpec>, Option<Recovery>), RecordError> {
    struct Each<'f>(&'f mut dyn FnMut(Entry));
    impl EntrySink for Each<'_> {
        fn channel(&mut self, _: &ChannelSpec) {}

        fn entry(&mut self, entry: Entry) {
            (self.0)(entry);
        }
    }
    read_into(path, &mut Each(each))
}

/// What a reading hands the channels and entries it reads to, in file
/// order; an entry's time counts from the test's start.
trait EntrySink {
    /// A sample channel, the next index [`Entry::Samples`] refers to.
    fn channel(&mut self, spec: &ChannelSpec);
    /// The next entry.
    fn entry(&mut self, entry: Entry);
}

impl EntrySink for Vec<Entry> {
    fn channel(&mut self, _: &ChannelSpec) {}

    fn entry(&mut self, entry: Entry) {
        self.push(entry);
    }
}

impl EntrySink for RecordBuilder {
    fn channel(&mut self, spec: &ChannelSpec) {
        self.add_channel(spec);
    }

    fn entry(&mut self, entry: Entry) {
        self.push(&entry);
    }
}

/// Reads a record file, handing its channels and entries to `sink` as
/// they are read (those before the `motorbench.test` metadata once it is
/// read); its metadata, sample channels and what was lost if it is
/// damaged. See the module docs for what is refused.
fn read_into(
    path: &Path,
    sink: &mut dyn EntrySink,
) -> Result<(TestMeta, Vec<ChannelSpec>, Option<Recovery>), RecordError> {
    let io = |e| RecordError::io(path, e);
    let file = File::open(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len();
    let mut source = BufReader::with_capacity(1 << 16, file);

    let mut state = Reading::new(path, sink);
    let mut header_seen = false;
    // What was cut, in a recovered copy of a cut record.
    let mut recovered: Option<BTreeMap<String, String>> = None;
    let damage = walk_source(&mut source, file_len, &mut |record| match record {
        McapRecord::Header(_) => header_seen = true,
        McapRecord::Metadata(m) if m.name == METADATA_NAME => state.metadata(&m.metadata),
        McapRecord::Metadata(m) if m.name == METADATA_RECOVERY => recovered = Some(m.metadata),
        // The first content error; reported only if the metadata is in
        // order (a file of another schema_version is refused as such).
        _ if state.failure.is_some() => {}
        other => {
            if let Err(e) = state.take(other) {
                state.failure = Some(e);
            }
        }
    })
    .map_err(io)?;
    let damaged = |d: &Damage, context: &str| RecordError::Damaged {
        path: path.to_path_buf(),
        offset: d.offset,
        reason: format!("{}{context}", damage_text(d, file_len)),
    };
    if let (Some(d), false) = (&damage, header_seen) {
        return Err(damaged(d, " (not an MCAP file?)"));
    }

    let read = state.finish();
    let Some(read_meta) = read.meta else {
        return Err(match &damage {
            Some(d) => damaged(d, &format!(" (no {METADATA_NAME} metadata before it)")),
            None => {
                RecordError::not_motorbench(path, format!("no {METADATA_NAME} metadata record"))
            }
        });
    };
    // Damage may be what broke the metadata or a message: say both.
    let meta = match (read_meta, read.failure, &damage) {
        (Ok((_, meta)), None, _) => meta,
        (Err(e), _, Some(d)) | (Ok(_), Some(e), Some(d)) => {
            let text = e.to_string();
            let prefix = format!("{}: ", path.display());
            let what = text.strip_prefix(&prefix).unwrap_or(&text);
            return Err(damaged(d, &format!(" (and before it: {what})")));
        }
        (Err(e), _, None) | (Ok(_), Some(e), None) => return Err(e),
    };
    if let Some(e) = read.before_start {
        return Err(e);
    }
    let recovery = damage
        .map(|d| Recovery {
            messages: read.messages,
            offset: d.offset,
            reason: damage_text(&d, file_len),
        })
        .or_else(|| recovered.as_ref().and_then(recovery_note));
    Ok((meta, read.channels, recovery))
}

/// The cut a recovered copy records (`motorbench.recovery`), as the cut
/// file read: so the copy reads as the cut file did.
fn recovery_note(note: &BTreeMap<String, String>) -> Option<Recovery> {
    Some(Recovery {
        messages: note.get(RECOVERY_MESSAGES)?.parse().ok()?,
        offset: note.get(RECOVERY_OFFSET)?.parse().ok()?,
        reason: note.get(RECOVERY_REASON)?.clone(),
    })
}

/// `damaged at byte 8 of 1200 (0.7 % read): <reason>`.
fn damage_text(d: &Damage, file_len: u64) -> String {
    format!(
        "damaged at byte {} of {file_len} ({:.1} % read): {}",
        d.offset,
        100.0 * d.offset as f64 / file_len.max(1) as f64,
        d.reason
    )
}

/// The metadata as read: the origin of `log_time` and the test's
/// metadata, or why they are refused.
type MetaRead = Result<(u64, TestMeta), RecordError>;

/// What a reading has found so far; entries go on to its sink.
struct Reading<'p, 's> {
    path: &'p Path,
    sink: &'s mut dyn EntrySink,
    routes: HashMap<u16, (String, Route)>,
    channels: Vec<ChannelSpec>,
    /// The first `motorbench.test` metadata record, read.
    meta: Option<MetaRead>,
    /// Entries read before the metadata (which gives their origin).
    early: Vec<Entry>,
    /// Sample values at one log time, not yet made an entry.
    pending: Option<(u64, Vec<(usize, f64)>)>,
    messages: u64,
    /// The first content error.
    failure: Option<RecordError>,
    /// The first message before the test's start.
    before_start: Option<RecordError>,
}

/// What [`Reading::finish`] leaves: everything but the entries.
struct Found {
    channels: Vec<ChannelSpec>,
    meta: Option<MetaRead>,
    messages: u64,
    failure: Option<RecordError>,
    before_start: Option<RecordError>,
}

impl<'p, 's> Reading<'p, 's> {
    fn new(path: &'p Path, sink: &'s mut dyn EntrySink) -> Self {
        Reading {
            path,
            sink,
            routes: HashMap::new(),
            channels: Vec::new(),
            meta: None,
            early: Vec::new(),
            pending: None,
            messages: 0,
            failure: None,
            before_start: None,
        }
    }

    /// Takes a `motorbench.test` metadata record (the first one only),
    /// handing on the entries read before it.
    fn metadata(&mut self, md: &BTreeMap<String, String>) {
        if self.meta.is_some() {
            return;
        }
        let path = self.path;
        self.meta =
            Some(meta_from(path, md).and_then(|meta| Ok((origin_ns(path, &meta, md)?, meta))));
        for entry in std::mem::take(&mut self.early) {
            self.emit(entry);
        }
    }

    /// Hands `entry` on with its time from the test's start; keeps it
    /// until the metadata says where that is.
    fn emit(&mut self, mut entry: Entry) {
        let origin = match &self.meta {
            None => return self.early.push(entry),
            Some(Ok((origin, _))) => *origin,
            // Refused at the end: nothing to hand on.
            Some(Err(_)) => return,
        };
        let t = entry.t_ns_mut();
        match t.checked_sub(origin) {
            Some(since_start) => {
                *t = since_start;
                self.sink.entry(entry);
            }
            None if self.before_start.is_none() => {
                self.before_start = Some(RecordError::not_motorbench(
                    self.path,
                    format!(
                        "a message at log_time {t} is before the test's start \
                         ({METADATA_START_TIME_NS} {origin})"
                    ),
                ));
            }
            None => {}
        }
    }

    /// Takes one data-section record (other than metadata).
    fn take(&mut self, record: McapRecord<'_>) -> Result<(), RecordError> {
        let path = self.path;
        match record {
            McapRecord::Channel(c) if !self.routes.contains_key(&c.id) => {
                let route = route_of(path, &c, &mut self.channels)?;
                if let Route::Sample(index) = route {
                    self.sink.channel(&self.channels[index]);
                }
                self.routes.insert(c.id, (c.topic, route));
            }
            McapRecord::Message { header, data } => {
                self.messages += 1;
                let Some((topic, route)) = self.routes.get(&header.channel_id) else {
                    return Err(RecordError::not_motorbench(
                        path,
                        format!(
                            "message at log_time {} on undeclared channel id {}",
                            header.log_time, header.channel_id
                        ),
                    ));
                };
                let t_ns = header.log_time;
                let bad = |reason: String| RecordError::BadMessage {
                    path: path.to_path_buf(),
                    topic: topic.clone(),
                    log_time: t_ns,
                    reason,
                };
                if let Route::Sample(index) = *route {
                    let s: SamplePayload = decode(&data).map_err(|e| bad(e.to_string()))?;
                    let value = (index, s.value);
                    match &mut self.pending {
                        Some((t, values)) if *t == t_ns => values.push(value),
                        _ => {
                            self.flush_pending();
                            self.pending = Some((t_ns, vec![value]));
                        }
                    }
                    return Ok(());
                }
                let entry = match route {
                    Route::Segment => Some(Entry::Segment {
                        t_ns,
                        marker: decode(&data).map_err(|e| bad(e.to_string()))?,
                    }),
                    Route::Event => Some(Entry::Event {
                        t_ns,
                        event: decode::<AnyEvent>(&data)
                            .map_err(|e| bad(e.to_string()))?
                            .into(),
                    }),
                    Route::Result => {
                        let report: serde_json::Value =
                            decode(&data).map_err(|e| bad(e.to_string()))?;
                        if !report.is_object() {
                            return Err(bad("the report is not a JSON object".into()));
                        }
                        Some(Entry::Result { t_ns, report })
                    }
                    Route::OperatingPoint => {
                        let point: OperatingPoint =
                            decode(&data).map_err(|e| bad(e.to_string()))?;
                        if let Some(t) = point.winding_temperature {
                            if let Some(why) = implausible_temperature(t) {
                                return Err(bad(format!("winding_temperature {t} {why}")));
                            }
                        }
                        Some(Entry::OperatingPoint { t_ns, point })
                    }
                    Route::SupplyLimit => Some(Entry::SupplyLimit {
                        t_ns,
                        limit: decode(&data).map_err(|e| bad(e.to_string()))?,
                    }),
                    Route::StandardTest => {
                        let reading: StandardTestReading =
                            decode(&data).map_err(|e| bad(e.to_string()))?;
                        if let Some(t) = reading.winding_temperature() {
                            if let Some(why) = implausible_temperature(t) {
                                return Err(bad(format!("winding_temperature {t} {why}")));
                            }
                        }
                        Some(Entry::StandardTest { t_ns, reading })
                    }
                    Route::Sample(_) | Route::Ignore => None,
                };
                if let Some(entry) = entry {
                    self.flush_pending();
                    self.emit(entry);
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn flush_pending(&mut self) {
        if let Some((t_ns, values)) = self.pending.take() {
            if !values.is_empty() {
                self.emit(Entry::Samples { t_ns, values });
            }
        }
    }

    /// Hands on the last entry; what was read besides the entries.
    fn finish(mut self) -> Found {
        self.flush_pending();
        Found {
            channels: self.channels,
            meta: self.meta,
            messages: self.messages,
            failure: self.failure,
            before_start: self.before_start,
        }
    }
}

fn decode<'a, T: Deserialize<'a>>(data: &'a [u8]) -> Result<T, DecodeError> {
    serde_json::from_slice(data).map_err(|source| {
        let text = String::from_utf8_lossy(data);
        DecodeError {
            shown: text.chars().take(80).collect(),
            cut: text.chars().count() > 80,
            source,
        }
    })
}

/// Routes a channel, adding sample channels to `channels`.
fn route_of(
    path: &Path,
    c: &mcap::records::Channel,
    channels: &mut Vec<ChannelSpec>,
) -> Result<Route, RecordError> {
    let is_sample = c.topic.starts_with(SENSOR_PREFIX) || c.topic.starts_with(COMMAND_PREFIX);
    let route = match c.topic.as_str() {
        _ if is_sample => Route::Sample(channels.len()),
        TOPIC_SEGMENT => Route::Segment,
        TOPIC_OPERATING_POINT => Route::OperatingPoint,
        TOPIC_EVENT => Route::Event,
        TOPIC_RESULT => Route::Result,
        TOPIC_SUPPLY_LIMIT => Route::SupplyLimit,
        TOPIC_STANDARD_TEST => Route::StandardTest,
        _ => return Ok(Route::Ignore),
    };
    if c.message_encoding != MESSAGE_ENCODING {
        return Err(RecordError::not_motorbench(
            path,
            format!(
                "channel {} has message encoding \"{}\", not \"{MESSAGE_ENCODING}\"",
                c.topic, c.message_encoding
            ),
        ));
    }
    if is_sample {
        let get = |key: &str| {
            c.metadata.get(key).cloned().ok_or_else(|| {
                RecordError::not_motorbench(
                    path,
                    format!("channel {} has no \"{key}\" metadata", c.topic),
                )
            })
        };
        let spec = ChannelSpec {
            topic: c.topic.clone(),
            quantity: get("quantity")?,
            unit: get("unit")?,
            source: get("source")?,
        };
        if !is_sample_topic_for(&spec.topic, &spec.quantity) {
            return Err(RecordError::not_motorbench(
                path,
                format!(
                    "channel {} has quantity \"{}\", which does not match its topic",
                    spec.topic, spec.quantity
                ),
            ));
        }
        channels.push(spec);
    }
    Ok(route)
}

/// The origin of `log_time` in a file of `meta`'s version, Unix ns: 0 in
/// version 1 (`log_time` counts from the start), the metadata's
/// `start_time_ns` from version 2 on.
fn origin_ns(
    path: &Path,
    meta: &TestMeta,
    md: &BTreeMap<String, String>,
) -> Result<u64, RecordError> {
    if meta.schema_version == "1" {
        return Ok(0);
    }
    let text = md.get(METADATA_START_TIME_NS).ok_or_else(|| {
        RecordError::not_motorbench(
            path,
            format!("{METADATA_NAME} metadata has no \"{METADATA_START_TIME_NS}\""),
        )
    })?;
    text.parse().map_err(|_| {
        RecordError::not_motorbench(
            path,
            format!(
                "{METADATA_NAME} {METADATA_START_TIME_NS} {} is not a whole number of ns",
                crate::excerpt::quoted(text)
            ),
        )
    })
}

/// The [`TestMeta`] of a `motorbench.test` metadata record.
fn meta_from(path: &Path, md: &BTreeMap<String, String>) -> Result<TestMeta, RecordError> {
    let get = |key: &str| {
        md.get(key).cloned().ok_or_else(|| {
            RecordError::not_motorbench(path, format!("{METADATA_NAME} metadata has no \"{key}\""))
        })
    };
    let schema_version = get("schema_version")?;
    if !READ_SCHEMA_VERSIONS.contains(&schema_version.as_str()) {
        return Err(RecordError::UnsupportedVersion {
            path: path.to_path_buf(),
            found: schema_version,
        });
    }
    let kind_text = get("kind")?;
    let kind = SegmentKind::parse(&kind_text).ok_or_else(|| {
        RecordError::not_motorbench(
            path,
            format!(
                "{METADATA_NAME} kind \"{kind_text}\" is not dc_step, dc_coastdown or im_slip_sweep"
            ),
        )
    })?;
    let motor_id = get("motor_id")?;
    let started_at = get("started_at")?;
    let nameplate_text = get("nameplate")?;
    let nameplate: serde_json::Value = serde_json::from_str(&nameplate_text).map_err(|e| {
        RecordError::not_motorbench(path, format!("{METADATA_NAME} nameplate is not JSON: {e}"))
    })?;
    if !nameplate.is_object() {
        return Err(RecordError::not_motorbench(
            path,
            format!("{METADATA_NAME} nameplate is not a JSON object"),
        ));
    }
    let config = get("config")?;
    Ok(TestMeta {
        schema_version,
        kind,
        motor_id,
        started_at,
        nameplate,
        config,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::types::{Event, EventLevel, SegmentPhase, SCHEMA_VERSION};
    use crate::record::writer::Recorder;
    use mcap::records::{MessageHeader, Metadata};
    use std::io::BufWriter;

    fn meta() -> TestMeta {
        TestMeta {
            schema_version: SCHEMA_VERSION.into(),
            kind: SegmentKind::DcStep,
            motor_id: "motor-7".into(),
            started_at: "2026-11-21T10:00:00Z".into(),
            nameplate: serde_json::json!({"power_W": 250.0, "voltage_V": 24.0, "current_A": 12.5, "speed_rpm": 3000.0}),
            config: "[test]\nkind = \"dc_step\"\n".into(),
        }
    }

    fn channels() -> Vec<ChannelSpec> {
        vec![
            ChannelSpec::sensor("armature_voltage", "V", "daq0"),
            ChannelSpec::sensor("armature_current", "A", "daq0"),
            ChannelSpec::sensor("speed", "rad/s", "enc0"),
            ChannelSpec::command("armature_voltage", "V", "psu0"),
        ]
    }

    /// A 10 s test at 1 kHz with two segments (0.001..=1.999 s and
    /// 1.999..=9.999 s), an event and a result.
    fn test_entries() -> Vec<Entry> {
        let mut out = vec![Entry::Event {
            t_ns: 0,
            event: Event {
                level: EventLevel::Info,
                message: "start".into(),
            },
        }];
        for k in 0..10_000u64 {
            let t = k * 1_000_000;
            if k == 1 {
                out.push(Entry::dc_step_marker(
                    t,
                    0,
                    SegmentPhase::Start,
                    "0 V → 12 V",
                ));
            }
            let x = k as f64 * 1e-3;
            out.push(Entry::Samples {
                t_ns: t,
                values: vec![
                    (0, 12.0 + 0.1 * x.sin()),
                    (1, (x * 3.7).cos() * 1.234_567_890_123),
                    (2, 100.0 * (1.0 - (-x).exp())),
                    (3, if k < 2000 { 12.0 } else { 6.0 }),
                ],
            });
            if k == 1999 {
                out.push(Entry::dc_step_marker(t, 0, SegmentPhase::End, "0 V → 12 V"));
                out.push(Entry::dc_step_marker(
                    t,
                    1,
                    SegmentPhase::Start,
                    "12 V → 6 V",
                ));
            }
        }
        out.push(Entry::dc_step_marker(
            9_999_000_000,
            1,
            SegmentPhase::End,
            "12 V → 6 V",
        ));
        out.push(Entry::Result {
            t_ns: 10_000_000_000,
            report: serde_json::json!({"schema_version": "1", "kind": "dc_step", "methods": {}, "best": null, "warnings": []}),
        });
        out
    }

    fn record_to(path: &Path, entries: &[Entry]) -> crate::record::RecorderStats {
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        rt.block_on(async {
            let rec = Recorder::start(path, &meta(), &channels(), 64).unwrap();
            for e in entries {
                rec.send(e.clone()).await.unwrap();
            }
            rec.finish().await.unwrap()
        })
    }

    fn live(entries: &[Entry]) -> Record {
        let mut b = RecordBuilder::new(Some(meta()), channels());
        for e in entries {
            b.push(e);
        }
        b.finish()
    }

    /// `(t, channel, value bits)` of every sample, in order.
    fn flat(entries: &[Entry]) -> Vec<(u64, usize, u64)> {
        entries
            .iter()
            .flat_map(|e| match e {
                Entry::Samples { t_ns, values } => values
                    .iter()
                    .map(|&(i, v)| (*t_ns, i, v.to_bits()))
                    .collect::<Vec<_>>(),
                _ => Vec::new(),
            })
            .collect()
    }

    #[test]
    fn round_trip_is_bit_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("awkward.mcap");
        let awkward = [
            0.1 + 0.2,
            1e-300,
            -0.0,
            0.0,
            123456.789e10,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            -f64::MAX,
            1.0 / 3.0,
            -2.5e-17,
            9007199254740991.0,
        ];
        let mut entries = vec![Entry::dc_step_marker(0, 0, SegmentPhase::Start, "awkward")];
        for (k, &v) in awkward.iter().enumerate() {
            entries.push(Entry::Samples {
                t_ns: k as u64 * 10,
                values: vec![(0, v), (1, -v), (2, v * 0.5), (3, v)],
            });
        }
        entries.push(Entry::Event {
            t_ns: 95,
            event: Event {
                level: EventLevel::Warn,
                message: "ünïcode \"quoted\"\nnewline".into(),
            },
        });
        entries.push(Entry::dc_step_marker(110, 0, SegmentPhase::End, "awkward"));
        let stats = record_to(&path, &entries);
        assert_eq!(stats.messages, awkward.len() as u64 * 4 + 3);

        let (m, chans, back, recovery) = read_entries(&path).unwrap();
        assert_eq!(m, meta());
        assert_eq!(chans, channels());
        assert!(recovery.is_none());
        assert_eq!(back, entries);
        // PartialEq on f64 treats -0.0 == 0.0: compare bits as well.
        assert_eq!(flat(&back), flat(&entries));
        let neg_zero = flat(&back)
            .into_iter()
            .find(|&(t, i, _)| t == 20 && i == 0)
            .unwrap();
        assert_eq!(neg_zero.2, (-0.0f64).to_bits());

        let replay = read_mcap(&path).unwrap();
        assert_eq!(replay, live(&entries));
        let seg = &replay.segments[0];
        assert_eq!(seg.current.len(), awkward.len());
        for (a, b) in seg.voltage.iter().zip(awkward) {
            assert_eq!(a.to_bits(), b.to_bits());
        }

        // The outline: every entry but the samples, which it counts.
        let outline = read_outline(&path).unwrap();
        assert_eq!(outline.meta, meta());
        let others: Vec<Entry> = entries
            .iter()
            .filter(|e| !matches!(e, Entry::Samples { .. }))
            .cloned()
            .collect();
        assert_eq!(outline.entries, others);
        assert_eq!(outline.samples, awkward.len() as u64 * 4);
        assert_eq!(outline.last_t_ns, 110);
        assert!(outline.recovery.is_none());
    }

    #[test]
    fn replay_equals_live_for_a_whole_test() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("test.mcap");
        let entries = test_entries();
        let stats = record_to(&path, &entries);
        assert_eq!(stats.per_topic["/sensor/speed"], 10_000);
        assert_eq!(stats.per_topic["/bench/segment"], 4);
        assert_eq!(stats.per_topic["/bench/operating_point"], 0);
        let (_, _, back, _) = read_entries(&path).unwrap();
        assert_eq!(flat(&back), flat(&entries));
        let replay = read_mcap(&path).unwrap();
        let want = live(&entries);
        assert_eq!(replay, want);
        assert_eq!(replay.segments.len(), 2);
        assert_eq!(replay.segments[0].time.len(), 1999);
        assert_eq!(replay.segments[1].time.len(), 8001);
        assert_eq!(replay.events.len(), 1);
        assert!(replay.recorded_result.is_some());
        for (a, b) in replay.segments.iter().zip(&want.segments) {
            for (x, y) in [
                (&a.time, &b.time),
                (&a.voltage, &b.voltage),
                (&a.current, &b.current),
                (&a.speed, &b.speed),
            ] {
                let xb: Vec<u64> = x.iter().map(|v| v.to_bits()).collect();
                let yb: Vec<u64> = y.iter().map(|v| v.to_bits()).collect();
                assert_eq!(xb, yb);
            }
        }
    }

    #[test]
    fn replay_equals_live_for_a_long_hold_read_as_its_head_and_tail() {
        // 100 s at 1 kHz in one step segment: a step settling in 20 ms,
        // then held, with alternating noise. Its samples are assigned to
        // the segment while it is being recorded (more than twice
        // thinning::PENDING of them), as in a live test.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("long.mcap");
        let n = 100_000u64;
        let mut entries = vec![Entry::dc_step_marker(0, 0, SegmentPhase::Start, "held")];
        for k in 0..n {
            let x =
                2.0 * (1.0 - (-(k as f64) / 20.0).exp()) + if k % 2 == 0 { 0.01 } else { -0.01 };
            entries.push(Entry::Samples {
                t_ns: k * 1_000_000,
                values: vec![(0, 24.0), (1, x), (2, 100.0 * x)],
            });
        }
        entries.push(Entry::dc_step_marker(
            (n - 1) * 1_000_000,
            0,
            SegmentPhase::End,
            "held",
        ));
        record_to(&path, &entries);
        let replay = read_mcap(&path).unwrap();
        assert_eq!(replay, live(&entries));
        let seg = &replay.segments[0];
        assert_eq!(
            seg.time.len(),
            crate::record::HEAD_SAMPLES + crate::record::TAIL_SAMPLES
        );
        assert_eq!(replay.notes.len(), 1);
        assert!(replay.notes[0].starts_with("held holds 100000 current readings over 100.0 s"));
        // Every sample is in the file.
        let (_, _, back, _) = read_entries(&path).unwrap();
        assert_eq!(flat(&back), flat(&entries));
    }

    #[test]
    fn non_finite_reading_becomes_a_warning_event() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nan.mcap");
        let entries = vec![
            Entry::Samples {
                t_ns: 0,
                values: vec![(0, 1.0), (1, f64::NAN), (2, 2.0)],
            },
            Entry::Samples {
                t_ns: 2,
                values: vec![(1, 3.0)],
            },
        ];
        let stats = record_to(&path, &entries);
        assert_eq!(stats.messages, 4, "three samples and one event");
        let (_, chans, back, _) = read_entries(&path).unwrap();
        let samples: Vec<(u64, usize, f64)> = back
            .iter()
            .flat_map(|e| match e {
                Entry::Samples { t_ns, values } => {
                    values.iter().map(|&(c, v)| (*t_ns, c, v)).collect()
                }
                _ => vec![],
            })
            .collect();
        assert_eq!(samples, vec![(0, 0, 1.0), (0, 2, 2.0), (2, 1, 3.0)]);
        let events: Vec<&Event> = back
            .iter()
            .filter_map(|e| match e {
                Entry::Event { t_ns: 0, event } => Some(event),
                _ => None,
            })
            .collect();
        assert_eq!(events.len(), 1);
        assert_eq!(events[0].level, EventLevel::Warn);
        assert!(events[0].message.contains("NaN") && events[0].message.contains(&chans[1].topic));
    }

    #[test]
    fn truncated_file_reads_a_prefix_with_recovery() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("full.mcap");
        let entries = test_entries();
        record_to(&path, &entries);
        let bytes = std::fs::read(&path).unwrap();
        let all = flat(&entries);
        for frac in [0.5, 0.999] {
            let cut = dir.path().join(format!("cut-{frac}.mcap"));
            let n = (bytes.len() as f64 * frac) as usize;
            std::fs::write(&cut, &bytes[..n]).unwrap();
            let (m, chans, back, recovery) = read_entries(&cut).unwrap();
            assert_eq!(m, meta());
            assert_eq!(chans, channels());
            let recovery = recovery.expect("a cut file is damaged");
            assert!(!recovery.reason.is_empty());
            let got = flat(&back);
            assert!(!got.is_empty(), "{frac}");
            assert_eq!(got[..], all[..got.len()], "{frac}: a prefix");
            if frac < 0.9 {
                assert!(got.len() < all.len());
                // At most a second (4 channels at 1 kHz) more than half.
                assert!(got.len() > all.len() / 4, "{} of {}", got.len(), all.len());
            } else {
                assert_eq!(got.len(), all.len(), "only the summary was cut");
            }
            let record = read_mcap(&cut).unwrap();
            assert_eq!(
                record.recovery.as_ref().unwrap().messages,
                recovery.messages
            );
            if frac < 0.9 {
                // The second segment is open: it keeps its start, loses its end.
                let last = record.segments.last().unwrap();
                assert!(last.label.ends_with(" (incomplete)"), "{}", last.label);
                assert!(record.recorded_result.is_none());
            } else {
                assert_eq!(record.segments, live(&entries).segments);
            }
        }
    }

    #[test]
    fn killed_writer_loses_at_most_about_a_second() {
        // A writer that is never finished (as if the process were killed):
        // only what the 1 s flushes put on disk survives.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("killed.mcap");
        let entries = test_entries();
        record_to(&path, &entries);
        // Reproduce the on-disk state at a kill: keep the bytes up to the
        // end of the last chunk that starts before the 5.5 s mark.
        let bytes = std::fs::read(&path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let mut chunks = summary.chunk_indexes.clone();
        chunks.sort_by_key(|c| c.chunk_start_offset);
        let kept = chunks
            .iter()
            // log_time is wall clock: the start (meta's started_at) + t.
            .rfind(|c| c.message_end_time <= 1_795_255_200_000_000_000 + 5_500_000_000)
            .unwrap();
        let end = (kept.chunk_start_offset + kept.chunk_length) as usize;
        let cut = dir.path().join("cut.mcap");
        std::fs::write(&cut, &bytes[..end]).unwrap();
        let (_, _, back, recovery) = read_entries(&cut).unwrap();
        assert!(recovery.is_some());
        let last_t = flat(&back).last().unwrap().0;
        assert!(last_t >= 4_500_000_000, "lost more than a second: {last_t}");
        // Chunks are closed at least every second of log time.
        for c in &chunks {
            assert!(
                c.message_end_time - c.message_start_time <= 1_000_000_000,
                "{:?}",
                chunks
                    .iter()
                    .map(|c| (c.message_start_time, c.message_end_time))
                    .collect::<Vec<_>>()
            );
        }
    }

    fn raw_file(path: &Path, metadata: Option<BTreeMap<String, String>>, event: &[u8]) {
        raw_file_at(path, metadata, event, 42);
    }

    /// A file of `metadata` with one `event` at `log_time`.
    fn raw_file_at(
        path: &Path,
        metadata: Option<BTreeMap<String, String>>,
        event: &[u8],
        log_time: u64,
    ) {
        raw_file_ordered(path, metadata, event, log_time, false);
    }

    /// [`raw_file_at`], the metadata written after the event where
    /// `metadata_last` (the contract does not say where it goes).
    fn raw_file_ordered(
        path: &Path,
        metadata: Option<BTreeMap<String, String>>,
        event: &[u8],
        log_time: u64,
        metadata_last: bool,
    ) {
        let file = std::fs::File::create(path).unwrap();
        let mut w = mcap::WriteOptions::new()
            .create(BufWriter::new(file))
            .unwrap();
        let (first, last) = match metadata_last {
            false => (metadata, None),
            true => (None, metadata),
        };
        let write_metadata = |w: &mut mcap::Writer<_>, md: Option<BTreeMap<String, String>>| {
            if let Some(md) = md {
                w.write_metadata(&Metadata {
                    name: METADATA_NAME.into(),
                    metadata: md,
                })
                .unwrap();
            }
        };
        write_metadata(&mut w, first);
        let schema = w
            .add_schema(
                "motorbench.Event",
                "jsonschema",
                crate::record::schema::EVENT_JSON_SCHEMA.as_bytes(),
            )
            .unwrap();
        let ch = w
            .add_channel(schema, TOPIC_EVENT, "json", &BTreeMap::new())
            .unwrap();
        w.write_to_known_channel(
            &MessageHeader {
                channel_id: ch,
                sequence: 0,
                log_time,
                publish_time: log_time,
            },
            event,
        )
        .unwrap();
        write_metadata(&mut w, last);
        w.finish().unwrap();
    }

    fn good_metadata() -> BTreeMap<String, String> {
        BTreeMap::from([
            ("schema_version".into(), "1".into()),
            ("kind".into(), "dc_step".into()),
            ("motor_id".into(), "m".into()),
            ("started_at".into(), "2026-11-21T10:00:00Z".into()),
            ("nameplate".into(), "{}".into()),
            ("config".into(), String::new()),
        ])
    }

    const EVENT: &[u8] = br#"{"level":"info","message":"hi"}"#;

    #[test]
    fn missing_metadata_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("foreign.mcap");
        raw_file(&path, None, EVENT);
        let e = read_mcap(&path).unwrap_err();
        assert!(matches!(e, RecordError::NotMotorbench { .. }), "{e}");
        let s = e.to_string();
        assert!(
            s.contains("foreign.mcap") && s.contains("not a motorbench record"),
            "{s}"
        );
        assert!(s.contains("motorbench.test"), "{s}");
    }

    #[test]
    fn missing_metadata_key_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nokey.mcap");
        let mut md = good_metadata();
        md.remove("motor_id");
        raw_file(&path, Some(md), EVENT);
        let s = read_mcap(&path).unwrap_err().to_string();
        assert!(
            s.contains("not a motorbench record") && s.contains("motor_id"),
            "{s}"
        );
    }

    #[test]
    fn other_schema_version_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v2.mcap");
        let mut md = good_metadata();
        md.insert("schema_version".into(), "3".into());
        // A message that does not decode under version 1 does not hide
        // the version.
        raw_file(&path, Some(md), br#"{"level":"fatal","message":"x"}"#);
        let e = read_mcap(&path).unwrap_err();
        assert!(matches!(e, RecordError::UnsupportedVersion { .. }), "{e}");
        assert!(e.to_string().contains("schema_version \"3\""), "{e}");
    }

    #[test]
    fn minimal_foreign_writer_file_reads() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ok.mcap");
        raw_file(&path, Some(good_metadata()), EVENT);
        let r = read_mcap(&path).unwrap();
        assert_eq!(r.events.len(), 1);
        assert_eq!(r.events[0].0, 42);
        assert!(r.recovery.is_none());
    }

    fn v2_metadata() -> BTreeMap<String, String> {
        let mut md = good_metadata();
        md.insert("schema_version".into(), "2".into());
        md.insert("start_time_ns".into(), "1795255200000000000".into());
        md
    }

    const LOG: &[u8] = br#"{"timestamp":{"sec":1795255200,"nsec":42},"level":3,"message":"hi","name":"motorbench","file":"","line":0}"#;

    #[test]
    fn version_2_times_count_from_start_time_ns() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v2.mcap");
        raw_file_at(&path, Some(v2_metadata()), LOG, 1_795_255_200_000_000_042);
        let r = read_mcap(&path).unwrap();
        assert_eq!(
            r.events,
            vec![(
                42,
                Event {
                    level: EventLevel::Warn,
                    message: "hi".into()
                }
            )]
        );
        assert_eq!(r.meta.unwrap().schema_version, "2");
    }

    #[test]
    fn metadata_after_the_messages_reads_the_same() {
        let dir = tempfile::tempdir().unwrap();
        let first = dir.path().join("first.mcap");
        let last = dir.path().join("last.mcap");
        let t = 1_795_255_200_000_000_042;
        raw_file_ordered(&first, Some(v2_metadata()), LOG, t, false);
        raw_file_ordered(&last, Some(v2_metadata()), LOG, t, true);
        let (a, b) = (read_mcap(&first).unwrap(), read_mcap(&last).unwrap());
        assert_eq!(a.events.len(), 1);
        assert_eq!(a.events[0].0, 42);
        assert_eq!(a, b);
        assert_eq!(read_entries(&first).unwrap(), read_entries(&last).unwrap());
        // Before the start, wherever the start is said.
        raw_file_ordered(&last, Some(v2_metadata()), LOG, t - 43, true);
        let s = read_mcap(&last).unwrap_err().to_string();
        assert!(s.contains("before the test's start"), "{s}");
    }

    #[test]
    fn version_2_without_its_start_or_before_it_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("early.mcap");
        raw_file_at(&path, Some(v2_metadata()), LOG, 1_795_255_199_000_000_000);
        let s = read_mcap(&path).unwrap_err().to_string();
        assert!(s.contains("before the test's start"), "{s}");
        let path = dir.path().join("nostart.mcap");
        let mut md = v2_metadata();
        md.remove("start_time_ns");
        raw_file_at(&path, Some(md), LOG, 1_795_255_200_000_000_042);
        let s = read_mcap(&path).unwrap_err().to_string();
        assert!(s.contains("no \"start_time_ns\""), "{s}");
        let path = dir.path().join("badstart.mcap");
        let mut md = v2_metadata();
        md.insert("start_time_ns".into(), "2026-11-21".into());
        raw_file_at(&path, Some(md), LOG, 1_795_255_200_000_000_042);
        let s = read_mcap(&path).unwrap_err().to_string();
        assert!(s.contains("not a whole number of ns"), "{s}");
    }

    #[test]
    fn undecodable_message_names_file_topic_and_time() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.mcap");
        raw_file(&path, Some(good_metadata()), b"{\"level\":\"loud\"");
        let e = read_mcap(&path).unwrap_err();
        let s = e.to_string();
        assert!(matches!(e, RecordError::BadMessage { .. }), "{s}");
        assert!(
            s.contains("bad.mcap") && s.contains("/bench/event") && s.contains("42"),
            "{s}"
        );
    }

    #[test]
    fn not_an_mcap_file_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.mcap");
        std::fs::write(&path, "time_s,armature_voltage_V\n0,1\n").unwrap();
        let s = read_mcap(&path).unwrap_err().to_string();
        assert!(s.contains("x.mcap"), "{s}");
        let s = read_mcap(&dir.path().join("absent.mcap"))
            .unwrap_err()
            .to_string();
        assert!(s.contains("absent.mcap"), "{s}");
    }
}
