//! The recorder: writes a test to MCAP per the data contract.
//!
//! [`Recorder::start`] creates the file and writes everything that is known
//! before the first sample (header, the `motorbench.test` metadata, schemas
//! and channels). Entries then go through a bounded queue to a writer
//! thread, so MCAP writing and compression never run on the async reactor;
//! a full queue makes [`Recorder::send`] wait, it never drops an entry.
//!
//! Layout of the messages:
//!
//! - [`Entry::Samples`] with N values becomes N messages, one per channel,
//!   payload `{"value": <f64>}`. JSON cannot carry NaN or infinity: a
//!   non-finite value is not written as a sample; a `/bench/event` warning
//!   names the channel and the value at that time instead.
//! - Segment markers, events and the result go to their `/bench/*` topics;
//!   the result payload is the report JSON as it is; events in the shape
//!   of Foxglove's `foxglove.Log` ([`super::log_event`]).
//! - `log_time = publish_time` = the test's start (the metadata's
//!   `started_at`, also written as `start_time_ns`) + `t_ns`: wall-clock
//!   Unix time in ns (contract version 2); sequence numbers count up from
//!   0 per channel.
//!
//! Crash safety: the current chunk is closed and the file buffer flushed
//! whenever log time has advanced by 1 s or more since the last flush, and
//! after every segment marker, abort event and result. A killed process
//! loses about the last second; the reader recovers the rest.
//!
//! If the recorder is dropped without [`Recorder::finish`], the writer
//! thread still writes what was queued and the summary, in the background.
//!
//! [`Recorder::backlog`] watches the queue while the test runs: entries
//! waiting for the writer thread now, and the waits for room so far.

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions, Writer};
use serde::Serialize;
use tokio::sync::{mpsc, oneshot};

use super::error::RecordError;
use super::log_event::LogMessage;
use super::schema::{
    is_sample_topic_for, BENCH_TOPICS, MESSAGE_ENCODING, METADATA_NAME, METADATA_START_TIME_NS,
    SAMPLE_JSON_SCHEMA, SCHEMA_ENCODING, SCHEMA_SAMPLE, TOPIC_EVENT, TOPIC_OPERATING_POINT,
    TOPIC_RESULT, TOPIC_SEGMENT, TOPIC_STANDARD_TEST, TOPIC_SUPPLY_LIMIT,
};
use super::start::TestStart;
use super::types::{ChannelSpec, Entry, Event, EventLevel, TestMeta, SCHEMA_VERSION};

/// Log time between two flushes, ns.
const FLUSH_INTERVAL_NS: u64 = 1_000_000_000;

/// Header `library` of every file we write.
pub fn library_name() -> String {
    format!("motorbench/{}", env!("CARGO_PKG_VERSION"))
}

/// What a finished recording wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecorderStats {
    /// Messages written, all topics.
    pub messages: u64,
    /// Messages written per topic; every declared topic is listed, with 0
    /// where nothing was written.
    pub per_topic: BTreeMap<String, u64>,
    /// How many times [`Recorder::send`] had to wait for room in the queue.
    pub backpressure_waits: u64,
    /// The file.
    pub path: PathBuf,
}

/// State shared by the recorder handle and its writer thread.
#[derive(Debug, Default)]
struct Shared {
    backpressure_waits: AtomicU64,
    /// Entries queued and not yet taken by the writer thread.
    queued: AtomicU64,
    /// The queue's capacity, entries.
    capacity: u64,
    /// The writer thread's error, once it has failed.
    failure: Mutex<Option<String>>,
}

/// Records one test to an MCAP file. See the module docs.
#[derive(Debug)]
pub struct Recorder {
    tx: mpsc::Sender<Entry>,
    done: oneshot::Receiver<Result<RecorderStats, RecordError>>,
    thread: std::thread::JoinHandle<()>,
    shared: Arc<Shared>,
    channel_count: usize,
    path: PathBuf,
}

/// The recorder's queue seen from outside: how far the writer thread is
/// behind. Cheap to clone; it does not keep the queue open.
#[derive(Debug, Clone)]
pub struct RecorderBacklog {
    shared: Arc<Shared>,
}

impl RecorderBacklog {
    /// Entries (one instant's readings, a marker, an event) queued and
    /// not yet taken by the writer thread.
    pub fn entries(&self) -> u64 {
        self.shared.queued.load(Ordering::Relaxed)
    }

    /// The queue's capacity, entries.
    pub fn capacity(&self) -> u64 {
        self.shared.capacity
    }

    /// Times an entry has waited for room in the full queue so far.
    pub fn waits(&self) -> u64 {
        self.shared.backpressure_waits.load(Ordering::Relaxed)
    }
}

/// Channel ids and counters, owned by the writer thread. Positions
/// `0..n` are the sample channels in the caller's order, then the
/// `/bench/*` topics in [`BENCH_TOPICS`] order.
struct Channels {
    /// The test's start, Unix ns: `log_time` = this + the entry's time.
    origin_ns: u64,
    topics: Vec<String>,
    ids: Vec<u16>,
    sequence: Vec<u32>,
    counts: Vec<u64>,
    samples: usize,
}

impl Channels {
    /// The MCAP `log_time` of an entry `t_ns` after the start.
    fn log_time(&self, t_ns: u64) -> u64 {
        self.origin_ns.saturating_add(t_ns)
    }

    fn position_of_bench(&self, topic: &str) -> usize {
        let k = BENCH_TOPICS
            .iter()
            .position(|(t, _, _)| *t == topic)
            .expect("a /bench topic of the contract");
        self.samples + k
    }
}

/// The recorder queue length every test records with, in entries (one
/// entry is one instant's readings): the CLI's and the daemon's, DC and
/// induction machine alike.
pub const QUEUE_CAPACITY: usize = 4096;

/// Most entries the writer thread takes from the queue at once.
const RECV_BATCH: usize = 256;

#[derive(Serialize)]
struct SamplePayload {
    /// Always finite (non-finite readings become events).
    value: f64,
}

impl Recorder {
    /// Creates the file (refusing to overwrite an existing one), writes the
    /// header (profile `""`, library `motorbench/<version>`), the
    /// `motorbench.test` metadata, the schemas and the channels (the given
    /// sample channels with their `unit`/`quantity`/`source` metadata, then
    /// the four `/bench/*` topics), and starts the writer thread.
    ///
    /// `queue_capacity` is the number of entries the queue holds (at least
    /// 1). Refuses a `meta` whose `schema_version` is not
    /// [`SCHEMA_VERSION`], whose `started_at` is not an RFC 3339 UTC time
    /// (the origin of `log_time`) or whose nameplate is not a JSON object, and
    /// channels whose topic is not `/sensor/<quantity>` or
    /// `/command/<quantity>` or appears twice.
    pub fn start(
        path: &Path,
        meta: &TestMeta,
        channels: &[ChannelSpec],
        queue_capacity: usize,
    ) -> Result<Recorder, RecordError> {
        let start = validate(path, meta, channels)?;
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|e| RecordError::io(path, e))?;
        let options = WriteOptions::new()
            .profile("")
            .library(library_name())
            .compression(Some(Compression::Zstd))
            .use_chunks(true)
            .chunk_size(Some(WriteOptions::DEFAULT_CHUNK_SIZE))
            .compression_threads(0);
        let mcap_err = |e| RecordError::mcap(path, e);
        let mut writer = options.create(BufWriter::new(file)).map_err(mcap_err)?;
        writer
            .write_metadata(&Metadata {
                name: METADATA_NAME.to_string(),
                metadata: metadata_map(meta, start),
            })
            .map_err(mcap_err)?;

        let sample_schema = writer
            .add_schema(
                SCHEMA_SAMPLE,
                SCHEMA_ENCODING,
                SAMPLE_JSON_SCHEMA.as_bytes(),
            )
            .map_err(mcap_err)?;
        let mut table = Channels {
            origin_ns: start.unix_ns(),
            topics: Vec::new(),
            ids: Vec::new(),
            sequence: Vec::new(),
            counts: Vec::new(),
            samples: channels.len(),
        };
        for c in channels {
            let md = BTreeMap::from([
                ("unit".to_string(), c.unit.clone()),
                ("quantity".to_string(), c.quantity.clone()),
                ("source".to_string(), c.source.clone()),
            ]);
            let id = writer
                .add_channel(sample_schema, &c.topic, MESSAGE_ENCODING, &md)
                .map_err(mcap_err)?;
            table.topics.push(c.topic.clone());
            table.ids.push(id);
        }
        for (topic, name, text) in BENCH_TOPICS {
            let schema = writer
                .add_schema(name, SCHEMA_ENCODING, text.as_bytes())
                .map_err(mcap_err)?;
            let id = writer
                .add_channel(schema, topic, MESSAGE_ENCODING, &BTreeMap::new())
                .map_err(mcap_err)?;
            table.topics.push(topic.to_string());
            table.ids.push(id);
        }
        table.sequence = vec![0; table.ids.len()];
        table.counts = vec![0; table.ids.len()];
        // The declarations reach the disk before the first sample.
        writer.flush().map_err(mcap_err)?;

        let (tx, rx) = mpsc::channel(queue_capacity.max(1));
        let (done_tx, done) = oneshot::channel();
        let shared = Arc::new(Shared {
            capacity: queue_capacity.max(1) as u64,
            ..Shared::default()
        });
        let thread_shared = Arc::clone(&shared);
        let thread_path = path.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("mcap-writer".to_string())
            .spawn(move || {
                let mut rx = rx;
                let result = run(writer, &mut rx, table, &thread_path, &thread_shared);
                if let Err(e) = &result {
                    *thread_shared
                        .failure
                        .lock()
                        .unwrap_or_else(|p| p.into_inner()) = Some(e.to_string());
                    rx.close();
                }
                drop(rx);
                // The receiver is gone if the recorder was dropped unfinished.
                let _ = done_tx.send(result);
            })
            .map_err(|e| RecordError::io(path, e))?;

        Ok(Recorder {
            tx,
            done,
            thread,
            shared,
            channel_count: channels.len(),
            path: path.to_path_buf(),
        })
    }

    /// Queues an entry. Waits when the queue is full (never drops),
    /// counting each wait in [`RecorderStats::backpressure_waits`].
    ///
    /// Returns the writer's error if the writer thread has failed, and
    /// refuses (without writing anything) samples whose channel index is
    /// outside the channel list and results that are not JSON objects.
    pub async fn send(&self, entry: Entry) -> Result<(), RecordError> {
        if let Some(reason) = self.failure() {
            return Err(self.writer_failed(reason));
        }
        self.check(&entry)?;
        // Counted before it is queued, so that the writer thread never
        // takes an entry it has not been counted for.
        self.shared.queued.fetch_add(1, Ordering::Relaxed);
        let sent = match self.tx.try_send(entry) {
            Ok(()) => Ok(()),
            Err(mpsc::error::TrySendError::Full(entry)) => {
                self.shared
                    .backpressure_waits
                    .fetch_add(1, Ordering::Relaxed);
                self.tx.send(entry).await.map_err(|_| self.writer_stopped())
            }
            Err(mpsc::error::TrySendError::Closed(_)) => Err(self.writer_stopped()),
        };
        if sent.is_err() {
            self.shared.queued.fetch_sub(1, Ordering::Relaxed);
        }
        sent
    }

    /// A watch on the queue, for a live display while the test runs.
    pub fn backlog(&self) -> RecorderBacklog {
        RecorderBacklog {
            shared: Arc::clone(&self.shared),
        }
    }

    /// Closes the queue, lets the writer thread write the rest and the
    /// summary, and returns what was written.
    pub async fn finish(self) -> Result<RecorderStats, RecordError> {
        let Recorder {
            tx,
            done,
            thread,
            shared,
            path,
            ..
        } = self;
        drop(tx);
        let result = done.await;
        // The thread has sent its result (or died): joining is immediate.
        let panicked = thread.join().is_err();
        match result {
            Ok(Ok(mut stats)) => {
                stats.backpressure_waits = shared.backpressure_waits.load(Ordering::Relaxed);
                Ok(stats)
            }
            Ok(Err(e)) => Err(e),
            Err(_) => Err(RecordError::WriterFailed {
                path,
                reason: if panicked {
                    "the writer thread panicked".to_string()
                } else {
                    "the writer thread ended without a result".to_string()
                },
            }),
        }
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn failure(&self) -> Option<String> {
        self.shared
            .failure
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    fn writer_failed(&self, reason: String) -> RecordError {
        RecordError::WriterFailed {
            path: self.path.clone(),
            reason,
        }
    }

    fn writer_stopped(&self) -> RecordError {
        let reason = self
            .failure()
            .unwrap_or_else(|| "the writer thread stopped".to_string());
        self.writer_failed(reason)
    }

    fn check(&self, entry: &Entry) -> Result<(), RecordError> {
        let reason = match entry {
            Entry::Samples { values, .. } => values
                .iter()
                .find(|(i, _)| *i >= self.channel_count)
                .map(|(i, _)| {
                    format!(
                        "sample for channel index {i}, but only {} channels were declared",
                        self.channel_count
                    )
                }),
            Entry::Result { report, .. } if !report.is_object() => {
                Some("the result report is not a JSON object".to_string())
            }
            Entry::OperatingPoint { point, .. } => point.non_finite_field().map(|(field, v)| {
                format!(
                    "operating point field {field} = {v} is not a finite number (JSON has none)"
                )
            }),
            Entry::StandardTest { reading, .. } => reading.non_finite_field().map(|(field, v)| {
                format!(
                    "standard-test reading field {field} = {v} is not a finite number (JSON has none)"
                )
            }),
            _ => None,
        };
        match reason {
            Some(reason) => Err(RecordError::InvalidInput {
                path: self.path.clone(),
                reason,
            }),
            None => Ok(()),
        }
    }
}

/// The `motorbench.test` metadata of `meta` started at `start` (all
/// values strings).
fn metadata_map(meta: &TestMeta, start: TestStart) -> BTreeMap<String, String> {
    BTreeMap::from([
        (
            METADATA_START_TIME_NS.to_string(),
            start.unix_ns().to_string(),
        ),
        ("schema_version".to_string(), meta.schema_version.clone()),
        ("kind".to_string(), meta.kind.as_str().to_string()),
        ("motor_id".to_string(), meta.motor_id.clone()),
        ("started_at".to_string(), meta.started_at.clone()),
        ("nameplate".to_string(), meta.nameplate.to_string()),
        ("config".to_string(), meta.config.clone()),
    ])
}

/// Checks what [`Recorder::start`] refuses; the test's start.
fn validate(
    path: &Path,
    meta: &TestMeta,
    channels: &[ChannelSpec],
) -> Result<TestStart, RecordError> {
    let invalid = |reason: String| RecordError::InvalidInput {
        path: path.to_path_buf(),
        reason,
    };
    if meta.schema_version != SCHEMA_VERSION {
        return Err(invalid(format!(
            "schema_version \"{}\" cannot be written (this build writes \"{SCHEMA_VERSION}\")",
            meta.schema_version
        )));
    }
    let start = TestStart::parse_rfc3339(&meta.started_at).ok_or_else(|| {
        invalid(format!(
            "started_at \"{}\" is not an RFC 3339 UTC time (e.g. 2026-12-03T15:48:50.123456789Z)",
            meta.started_at
        ))
    })?;
    if !meta.nameplate.is_object() {
        return Err(invalid("the nameplate is not a JSON object".to_string()));
    }
    for (i, c) in channels.iter().enumerate() {
        if !is_sample_topic_for(&c.topic, &c.quantity) {
            return Err(invalid(format!(
                "channel topic {} does not match quantity \"{}\" (want /sensor/{1} or /command/{1})",
                c.topic, c.quantity
            )));
        }
        if channels[..i].iter().any(|o| o.topic == c.topic) {
            return Err(invalid(format!(
                "channel topic {} is declared twice",
                c.topic
            )));
        }
    }
    Ok(start)
}

/// The writer thread's body: writes queued entries until the queue closes,
/// then the summary.
fn run(
    mut writer: Writer<BufWriter<File>>,
    rx: &mut mpsc::Receiver<Entry>,
    mut table: Channels,
    path: &Path,
    shared: &Shared,
) -> Result<RecorderStats, RecordError> {
    let mcap_err = |e| RecordError::mcap(path, e);
    let mut payload = Vec::with_capacity(64);
    let mut last_flush = 0u64;
    // Entries are taken as many as are queued at once: when the bench
    // sends faster than the file is written, one wake-up of the sender per
    // batch instead of per entry (the futex round trips were a quarter of
    // the writing time of a 1.54 M-sample record).
    let mut batch = Vec::with_capacity(RECV_BATCH);
    while rx.blocking_recv_many(&mut batch, RECV_BATCH) > 0 {
        shared
            .queued
            .fetch_sub(batch.len() as u64, Ordering::Relaxed);
        for entry in batch.drain(..) {
            let (t_ns, urgent) =
                write_entry(&mut writer, &mut table, &mut payload, &entry).map_err(mcap_err)?;
            if urgent || t_ns >= last_flush.saturating_add(FLUSH_INTERVAL_NS) {
                // Closes the chunk and flushes the BufWriter into the file.
                writer.flush().map_err(mcap_err)?;
                last_flush = last_flush.max(t_ns);
            }
        }
    }
    writer.finish().map_err(mcap_err)?;
    let file = writer
        .into_inner()
        .into_inner()
        .map_err(|e| RecordError::io(path, e.into_error()))?;
    file.sync_all().map_err(|e| RecordError::io(path, e))?;

    let per_topic: BTreeMap<String, u64> = table
        .topics
        .iter()
        .cloned()
        .zip(table.counts.iter().copied())
        .collect();
    Ok(RecorderStats {
        messages: table.counts.iter().sum(),
        per_topic,
        backpressure_waits: 0,
        path: path.to_path_buf(),
    })
}

/// Write one queued entry: its time and whether it must reach the disk at
/// once (a segment marker, an abort, a point, a result).
fn write_entry(
    writer: &mut Writer<BufWriter<File>>,
    table: &mut Channels,
    payload: &mut Vec<u8>,
    entry: &Entry,
) -> Result<(u64, bool), mcap::McapError> {
    Ok(match entry {
        Entry::Samples { t_ns, values } => {
            for &(index, value) in values {
                if value.is_finite() {
                    payload.clear();
                    serde_json::to_writer(&mut *payload, &SamplePayload { value })
                        .expect("serializing a sample cannot fail");
                    write_message(writer, table, index, *t_ns, payload)?;
                } else {
                    // JSON has no NaN or infinity: say so on /bench/event
                    // instead of losing the reading silently.
                    let event = Event {
                        level: EventLevel::Warn,
                        message: format!(
                            "non-finite reading ({value}) on {} not representable in JSON; \
                             not recorded as a sample",
                            table.topics[index]
                        ),
                    };
                    write_event(writer, table, *t_ns, &event)?;
                }
            }
            (*t_ns, false)
        }
        Entry::Segment { t_ns, marker } => {
            write_bench_json(
                writer,
                table,
                TOPIC_SEGMENT,
                *t_ns,
                marker,
                "a marker serializes",
            )?;
            (*t_ns, true)
        }
        Entry::Event { t_ns, event } => {
            write_event(writer, table, *t_ns, event)?;
            (*t_ns, event.level == EventLevel::Abort)
        }
        Entry::OperatingPoint { t_ns, point } => {
            write_bench_json(
                writer,
                table,
                TOPIC_OPERATING_POINT,
                *t_ns,
                point,
                "a point serializes",
            )?;
            (*t_ns, true)
        }
        Entry::SupplyLimit { t_ns, limit } => {
            write_bench_json(
                writer,
                table,
                TOPIC_SUPPLY_LIMIT,
                *t_ns,
                limit,
                "a supply limit serializes",
            )?;
            (*t_ns, true)
        }
        Entry::StandardTest { t_ns, reading } => {
            write_bench_json(
                writer,
                table,
                TOPIC_STANDARD_TEST,
                *t_ns,
                reading,
                "a standard-test reading serializes",
            )?;
            (*t_ns, true)
        }
        Entry::Result { t_ns, report } => {
            write_bench_json(
                writer,
                table,
                TOPIC_RESULT,
                *t_ns,
                report,
                "a JSON value serializes",
            )?;
            (*t_ns, true)
        }
    })
}

/// Write `value` as JSON on the `/bench` topic `topic` at `t_ns`; `what`
/// is the panic message should it not serialize.
fn write_bench_json(
    writer: &mut Writer<BufWriter<File>>,
    table: &mut Channels,
    topic: &str,
    t_ns: u64,
    value: &impl Serialize,
    what: &str,
) -> Result<(), mcap::McapError> {
    let pos = table.position_of_bench(topic);
    let data = serde_json::to_vec(value).expect(what);
    write_message(writer, table, pos, t_ns, &data)
}

/// Write `event` on `/bench/event` at `t_ns`, as `foxglove.Log`.
fn write_event(
    writer: &mut Writer<BufWriter<File>>,
    table: &mut Channels,
    t_ns: u64,
    event: &Event,
) -> Result<(), mcap::McapError> {
    let log = LogMessage::new(event, table.log_time(t_ns));
    write_bench_json(
        writer,
        table,
        TOPIC_EVENT,
        t_ns,
        &log,
        "an event serializes",
    )
}

fn write_message(
    writer: &mut Writer<BufWriter<File>>,
    table: &mut Channels,
    pos: usize,
    t_ns: u64,
    data: &[u8],
) -> Result<(), mcap::McapError> {
    let header = MessageHeader {
        channel_id: table.ids[pos],
        sequence: table.sequence[pos],
        log_time: table.log_time(t_ns),
        publish_time: table.log_time(t_ns),
    };
    writer.write_to_known_channel(&header, data)?;
    table.sequence[pos] = table.sequence[pos].wrapping_add(1);
    table.counts[pos] += 1;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::types::{Event, SegmentKind};
    use std::time::{Duration, Instant};

    fn meta() -> TestMeta {
        TestMeta {
            schema_version: SCHEMA_VERSION.into(),
            kind: SegmentKind::DcCoastdown,
            motor_id: "m".into(),
            started_at: "2026-11-21T10:00:00Z".into(),
            nameplate: serde_json::json!({"power_W": 100.0}),
            config: String::new(),
        }
    }

    fn channels() -> Vec<ChannelSpec> {
        vec![
            ChannelSpec::sensor("armature_current", "A", "daq"),
            ChannelSpec::sensor("speed", "rad/s", "enc"),
        ]
    }

    fn runtime() -> tokio::runtime::Runtime {
        tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .build()
            .unwrap()
    }

    fn samples(t_ns: u64) -> Entry {
        Entry::Samples {
            t_ns,
            values: vec![(0, t_ns as f64), (1, 2.0)],
        }
    }

    /// Polls `f` for up to 10 s.
    fn eventually(mut f: impl FnMut() -> bool) -> bool {
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(10) {
            if f() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }

    #[test]
    fn writes_header_metadata_and_stats() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.mcap");
        let stats = runtime().block_on(async {
            let rec = Recorder::start(&path, &meta(), &channels(), 8).unwrap();
            assert_eq!(rec.path(), path);
            for k in 0..100 {
                rec.send(samples(k * 1_000_000)).await.unwrap();
            }
            rec.send(Entry::Event {
                t_ns: 5,
                event: Event {
                    level: EventLevel::Abort,
                    message: "limit".into(),
                },
            })
            .await
            .unwrap();
            rec.finish().await.unwrap()
        });
        assert_eq!(stats.messages, 201);
        assert_eq!(stats.path, path);
        assert_eq!(stats.per_topic.len(), 8);
        assert_eq!(stats.per_topic["/bench/supply_limit"], 0);
        assert_eq!(stats.per_topic["/sensor/armature_current"], 100);
        assert_eq!(stats.per_topic["/bench/event"], 1);
        assert_eq!(stats.per_topic["/bench/result"], 0);

        let bytes = std::fs::read(&path).unwrap();
        let mut header = None;
        let mut metadata = None;
        for r in mcap::read::LinearReader::new(&bytes).unwrap() {
            match r.unwrap() {
                mcap::records::Record::Header(h) => header = Some(h),
                mcap::records::Record::Metadata(m) => metadata = Some(m),
                _ => {}
            }
        }
        let header = header.unwrap();
        assert_eq!(header.profile, "");
        assert_eq!(
            header.library,
            format!("motorbench/{}", env!("CARGO_PKG_VERSION"))
        );
        let md = metadata.unwrap();
        assert_eq!(md.name, "motorbench.test");
        assert_eq!(md.metadata["schema_version"], "2");
        // The start to the ns, as the origin of log_time.
        assert_eq!(md.metadata["started_at"], "2026-11-21T10:00:00Z");
        assert_eq!(md.metadata["start_time_ns"], "1795255200000000000");
        assert_eq!(md.metadata["kind"], "dc_coastdown");
        assert_eq!(md.metadata["nameplate"], r#"{"power_W":100.0}"#);

        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(summary.stats.unwrap().message_count, 201);
        assert!(summary
            .chunk_indexes
            .iter()
            .all(|c| c.compression == "zstd"));
        let speed = summary
            .channels
            .values()
            .find(|c| c.topic == "/sensor/speed")
            .unwrap();
        assert_eq!(speed.message_encoding, "json");
        assert_eq!(speed.metadata["unit"], "rad/s");
        assert_eq!(speed.metadata["quantity"], "speed");
        assert_eq!(speed.metadata["source"], "enc");
        let schema = speed.schema.as_ref().unwrap();
        assert_eq!(schema.name, "motorbench.Sample");
        assert_eq!(schema.encoding, "jsonschema");

        // Sequence numbers count up per channel; log_time == publish_time,
        // the wall clock: the start plus the entry's time.
        let mut seq: BTreeMap<String, Vec<u32>> = BTreeMap::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            assert_eq!(m.log_time, m.publish_time);
            if m.channel.topic == "/sensor/speed" {
                let t_ns = 1_000_000 * u64::from(m.sequence);
                assert_eq!(m.log_time, 1_795_255_200_000_000_000 + t_ns);
            }
            if m.channel.topic == "/bench/event" {
                assert_eq!(m.channel.schema.as_ref().unwrap().name, "foxglove.Log");
                let log: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
                assert_eq!(log["level"], 4, "abort is Foxglove's ERROR");
                assert_eq!(log["message"], "limit");
                assert_eq!(
                    log["timestamp"],
                    serde_json::json!({"sec": 1_795_255_200u64, "nsec": 5})
                );
            }
            seq.entry(m.channel.topic.clone())
                .or_default()
                .push(m.sequence);
        }
        assert_eq!(seq["/sensor/speed"], (0..100).collect::<Vec<u32>>());
    }

    #[test]
    fn refuses_to_overwrite() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("exists.mcap");
        std::fs::write(&path, b"keep me").unwrap();
        let e = Recorder::start(&path, &meta(), &channels(), 8).unwrap_err();
        assert!(matches!(e, RecordError::Io { .. }), "{e}");
        assert!(e.to_string().contains("exists.mcap"), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), b"keep me");
    }

    #[test]
    fn refuses_bad_input() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.mcap");
        let mut m = meta();
        m.schema_version = "1".into();
        assert!(Recorder::start(&path, &m, &channels(), 8).is_err());
        let mut m = meta();
        m.started_at = "2026-11-21 10:00".into();
        let e = Recorder::start(&path, &m, &channels(), 8).unwrap_err();
        assert!(e.to_string().contains("started_at"), "{e}");
        let mut m = meta();
        m.nameplate = serde_json::json!([1]);
        assert!(Recorder::start(&path, &m, &channels(), 8).is_err());
        let mut c = channels();
        c[0].topic = "/sensor/current".into();
        let e = Recorder::start(&path, &meta(), &c, 8).unwrap_err();
        assert!(e.to_string().contains("/sensor/current"), "{e}");
        let mut c = channels();
        c.push(c[0].clone());
        assert!(Recorder::start(&path, &meta(), &c, 8).is_err());
        assert!(!path.exists(), "nothing is created for refused input");

        runtime().block_on(async {
            let rec = Recorder::start(&path, &meta(), &channels(), 8).unwrap();
            let e = rec
                .send(Entry::Samples {
                    t_ns: 0,
                    values: vec![(0, 1.0), (2, 1.0)],
                })
                .await
                .unwrap_err();
            assert!(matches!(e, RecordError::InvalidInput { .. }), "{e}");
            let e = rec
                .send(Entry::Result {
                    t_ns: 0,
                    report: serde_json::json!("text"),
                })
                .await
                .unwrap_err();
            assert!(e.to_string().contains("not a JSON object"), "{e}");
            // The recorder goes on.
            rec.send(samples(1)).await.unwrap();
            let stats = rec.finish().await.unwrap();
            assert_eq!(stats.messages, 2);
        });
    }

    #[test]
    fn full_queue_waits_and_never_drops() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bp.mcap");
        let n = 20_000u64;
        let (stats, backlog, most) = runtime().block_on(async {
            let rec = Recorder::start(&path, &meta(), &channels(), 1).unwrap();
            let backlog = rec.backlog();
            let mut most = 0;
            for k in 0..n {
                rec.send(samples(k * 1_000)).await.unwrap();
                most = most.max(backlog.entries());
            }
            (rec.finish().await.unwrap(), backlog, most)
        });
        assert_eq!(stats.messages, 2 * n);
        assert!(stats.backpressure_waits > 0);
        assert!(stats.backpressure_waits <= n);
        // The backlog never showed more than the queue holds (plus the one
        // entry counted on its way in), and it is empty at the end.
        assert_eq!(backlog.capacity(), 1);
        assert!(most <= 2, "backlog peaked at {most}");
        assert_eq!(backlog.entries(), 0);
        assert_eq!(backlog.waits(), stats.backpressure_waits);
    }

    #[test]
    fn data_reaches_the_disk_while_recording() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("live.mcap");
        let rt = runtime();
        let rec = Recorder::start(&path, &meta(), &channels(), 64).unwrap();
        rt.block_on(async {
            // 2.5 s of log time at 100 Hz.
            for k in 0..250u64 {
                rec.send(samples(k * 10_000_000)).await.unwrap();
            }
        });
        // Unfinished: the reader sees the flushed prefix (up to 2 s).
        let ok = eventually(|| match crate::record::read_entries(&path) {
            Ok((_, _, entries, recovery)) => {
                recovery.is_some()
                    && entries
                        .iter()
                        .any(|e| matches!(e, Entry::Samples { t_ns, .. } if *t_ns >= 2_000_000_000))
            }
            Err(_) => false,
        });
        assert!(ok, "the first 2 s were not flushed");
        let stats = rt.block_on(rec.finish()).unwrap();
        assert_eq!(stats.messages, 500);
    }

    #[test]
    fn dropped_recorder_still_finishes_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("dropped.mcap");
        runtime().block_on(async {
            let rec = Recorder::start(&path, &meta(), &channels(), 8).unwrap();
            for k in 0..10 {
                rec.send(samples(k)).await.unwrap();
            }
        });
        let ok = eventually(|| {
            std::fs::read(&path)
                .ok()
                .and_then(|b| mcap::Summary::read(&b).ok().flatten())
                .and_then(|s| s.stats)
                .is_some_and(|s| s.message_count == 20)
        });
        assert!(ok);
    }

    #[test]
    fn operating_points_round_trip_and_non_finite_ones_are_refused() {
        use crate::record::{read_mcap, OperatingPoint};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("im.mcap");
        let point = |slip: f64, torque: Option<f64>| OperatingPoint {
            segment: 0,
            slip,
            line_voltage: 400.0,
            line_current: 7.5,
            input_power: 3100.0,
            speed: (1.0 - slip) * 157.08,
            frequency: 50.0,
            torque,
            // A point with a torque sensor here has a thermometer too.
            winding_temperature: torque.map(|t| t + 20.5),
        };
        let stats = runtime().block_on(async {
            let rec = Recorder::start(&path, &meta(), &channels(), 8).unwrap();
            rec.send(Entry::OperatingPoint {
                t_ns: 1,
                point: point(0.03, Some(25.0)),
            })
            .await
            .unwrap();
            rec.send(Entry::OperatingPoint {
                t_ns: 2,
                point: point(1.0, None),
            })
            .await
            .unwrap();
            let mut bad = point(0.5, None);
            bad.frequency = f64::NAN;
            let e = rec
                .send(Entry::OperatingPoint {
                    t_ns: 3,
                    point: bad,
                })
                .await
                .unwrap_err();
            assert!(e.to_string().contains("frequency"), "{e}");
            rec.finish().await.unwrap()
        });
        assert_eq!(stats.per_topic["/bench/operating_point"], 2);
        // A point without a thermometer's reading has no such key: its
        // message is as before the key was added, and such a message
        // still reads.
        let json = |p: OperatingPoint| serde_json::to_string(&p).unwrap();
        assert!(
            json(point(0.03, Some(25.0))).ends_with(r#""torque":25.0,"winding_temperature":45.5}"#)
        );
        let old = json(point(1.0, None));
        assert!(old.ends_with(r#""torque":null}"#), "{old}");
        assert_eq!(
            serde_json::from_str::<OperatingPoint>(&old).unwrap(),
            point(1.0, None)
        );
        let record = read_mcap(&path).unwrap();
        assert_eq!(
            record.operating_points,
            vec![point(0.03, Some(25.0)), point(1.0, None)]
        );
    }
}
