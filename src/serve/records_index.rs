//! The records directory and its index: one entry per test (name, rig,
//! motor id, plan, start, outcome, key results, files), kept in
//! `index.json` beside the records and written atomically (a temporary
//! file, fsync, rename, fsync of the directory), so it survives restarts
//! and crashes.
//!
//! On open, entries still marked `running` belong to a daemon that died
//! mid-test: they become `interrupted`, with what the MCAP reader could
//! recover, or `unanalysed` when the plan had ended and only the analysis
//! was cut short (`data_complete`), unless the record already holds its
//! `/bench/result` (the identification is written before the diagnosis):
//! then `completed` or `aborted` with its key results, the reason saying
//! what is missing. MCAP files the index does not know (a
//! new or a cut index) are added from the records themselves: metadata,
//! result and abort event; [`RecordsIndex::adopt_orphans`] gives them
//! their rig.
//! [`RecordsIndex::apply_retention`] deletes a rig's oldest finished
//! records beyond its size and age limits.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::config::Retention;
use crate::record::{read_outline, Entry, EventLevel, Outline};

/// File name of the index in the records directory.
pub const INDEX_FILE: &str = "index.json";

/// Version of the index file layout.
const INDEX_VERSION: u32 = 1;

/// How a recorded test ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum RecordOutcome {
    /// The test is running now.
    Running,
    /// Every step of the plan ran.
    Completed,
    /// The test was stopped and the rig made safe (cause in `reason`).
    Aborted,
    /// The daemon died during the test (found `running` on the next start).
    Interrupted,
    /// The plan ended and its data is recorded (every segment flushed),
    /// but the daemon stopped before the analysis finished: the record has
    /// no result; `motorbench replay NAME.mcap` reruns the analysis.
    Unanalysed,
    /// The daemon could not finish the test (a recording error).
    Failed,
}

impl RecordOutcome {
    /// The outcome's name, as in the index (`completed`, `aborted`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            RecordOutcome::Running => "running",
            RecordOutcome::Completed => "completed",
            RecordOutcome::Aborted => "aborted",
            RecordOutcome::Interrupted => "interrupted",
            RecordOutcome::Unanalysed => "unanalysed",
            RecordOutcome::Failed => "failed",
        }
    }
}

/// What could be read back from an interrupted record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Recovered {
    /// Messages read before the damage.
    pub messages: u64,
    /// Test time of the last entry read, s.
    pub last_t_s: f64,
    /// What the reader reported at the damage (none: the file was whole).
    pub damage: Option<String>,
}

/// Headline results: the best method and its parameter values (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct KeyResults {
    /// The method whose parameters to use.
    pub method: String,
    /// Parameter values by contract key (`Ra`, `K`, …).
    pub params: std::collections::BTreeMap<String, f64>,
}

/// One record in the index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct IndexEntry {
    /// Record name: the file stem, also the test id.
    pub name: String,
    /// Rig that ran it.
    pub rig: String,
    /// Motor under test.
    pub motor_id: String,
    /// Test kind (`dc_step`, …).
    pub kind: String,
    /// The plan, for a person (e.g. `dc_step 60 → 248 V`).
    pub plan: String,
    /// Wall-clock start, RFC 3339.
    pub started_at: String,
    /// Wall-clock start, s since the Unix epoch (for retention).
    pub started_unix_s: f64,
    /// Wall-clock end, RFC 3339.
    #[serde(default)]
    pub finished_at: Option<String>,
    /// How it ended.
    pub outcome: RecordOutcome,
    /// Why it was aborted, failed or interrupted.
    #[serde(default)]
    pub reason: Option<String>,
    /// Headline results, when identification gave some.
    #[serde(default)]
    pub key_results: Option<KeyResults>,
    /// The MCAP file name.
    pub mcap: String,
    /// The report file name, once written.
    #[serde(default)]
    pub report: Option<String>,
    /// The plot file name, once written.
    #[serde(default)]
    pub svg: Option<String>,
    /// The residual plot's file name (`NAME.residuals.svg`), once written
    /// (only a diagnosed record has one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residuals_svg: Option<String>,
    /// Size of the record's files, bytes.
    #[serde(default)]
    pub bytes: u64,
    /// For an interrupted record: what the reader recovered.
    #[serde(default)]
    pub recovered: Option<Recovered>,
    /// The plan has ended (the rig is safe) and the data is recorded; set
    /// when the analysis starts.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub data_complete: bool,
}

impl IndexEntry {
    /// The entry of a test that has just started recording to `<name>.mcap`.
    pub fn running(
        name: &str,
        rig: &str,
        motor_id: &str,
        kind: &str,
        plan: &str,
        started_at: String,
        started_unix_s: f64,
    ) -> IndexEntry {
        IndexEntry {
            name: name.to_string(),
            rig: rig.to_string(),
            motor_id: motor_id.to_string(),
            kind: kind.to_string(),
            plan: plan.to_string(),
            started_at,
            started_unix_s,
            finished_at: None,
            outcome: RecordOutcome::Running,
            reason: None,
            key_results: None,
            mcap: format!("{name}.mcap"),
            report: None,
            svg: None,
            residuals_svg: None,
            bytes: 0,
            recovered: None,
            data_complete: false,
        }
    }

    /// The record's files that exist (MCAP, report, plots).
    pub fn files(&self) -> Vec<&str> {
        std::iter::once(self.mcap.as_str())
            .chain(self.report.as_deref())
            .chain(self.svg.as_deref())
            .chain(self.residuals_svg.as_deref())
            .collect()
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct IndexFile {
    version: u32,
    records: Vec<IndexEntry>,
}

/// The index file as written: the entries borrowed, not copied.
#[derive(Serialize)]
struct IndexFileRef<'a> {
    version: u32,
    records: &'a [IndexEntry],
}

/// The index could not be read or written.
#[derive(Debug, Error)]
pub enum IndexError {
    /// A file or directory operation failed.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: String,
        /// The error.
        source: std::io::Error,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> IndexError + '_ {
    move |source| IndexError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Seconds since the Unix epoch.
pub fn unix_s(t: SystemTime) -> f64 {
    t.duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Runs `f` on the daemon's shared index under its lock, on tokio's
/// blocking pool: a save writes and fsyncs the file and its directory,
/// and on the reactor's thread that would stall every other task (the
/// live feed, the API, another rig's test) for as long as the disk takes.
pub async fn on_index<R: Send + 'static>(
    index: &Arc<tokio::sync::Mutex<RecordsIndex>>,
    f: impl FnOnce(&mut RecordsIndex) -> R + Send + 'static,
) -> R {
    with_locked(Arc::clone(index).lock_owned().await, f).await
}

/// [`on_index`] for a lock already held.
pub async fn with_locked<R: Send + 'static>(
    mut index: tokio::sync::OwnedMutexGuard<RecordsIndex>,
    f: impl FnOnce(&mut RecordsIndex) -> R + Send + 'static,
) -> R {
    match tokio::task::spawn_blocking(move || f(&mut index)).await {
        Ok(r) => r,
        Err(e) => match e.try_into_panic() {
            Ok(panic) => std::panic::resume_unwind(panic),
            Err(e) => panic!("the records index's task did not run: {e}"),
        },
    }
}

/// The records directory and its index. See the module docs.
#[derive(Debug)]
pub struct RecordsIndex {
    dir: PathBuf,
    entries: Vec<IndexEntry>,
}

impl RecordsIndex {
    /// Open (creating the directory if needed) and repair: `running`
    /// entries become `interrupted`, unknown MCAP files are added. Returns
    /// the index and the names it marked interrupted. A corrupt index file
    /// is kept aside as `index.json.corrupt` and rebuilt from the files.
    pub fn open(dir: &Path) -> Result<(RecordsIndex, Vec<String>), IndexError> {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        let path = dir.join(INDEX_FILE);
        let entries = match std::fs::read_to_string(&path) {
            Ok(text) => match serde_json::from_str::<IndexFile>(&text) {
                Ok(f) if f.version == INDEX_VERSION => f.records,
                Ok(f) => {
                    tracing::error!(
                        "{}: index version {} is not {INDEX_VERSION}; rebuilding it from the records",
                        path.display(),
                        f.version
                    );
                    set_aside(&path)?;
                    Vec::new()
                }
                Err(e) => {
                    tracing::error!(
                        "{}: unreadable index ({e}); kept as {INDEX_FILE}.corrupt, rebuilding it from the records",
                        path.display()
                    );
                    set_aside(&path)?;
                    Vec::new()
                }
            },
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
            Err(e) => return Err(io_err(&path)(e)),
        };
        let mut index = RecordsIndex {
            dir: dir.to_path_buf(),
            entries,
        };
        let mut interrupted = Vec::new();
        for e in &mut index.entries {
            if e.outcome == RecordOutcome::Running {
                let read = read_outline(&dir.join(&e.mcap));
                // The analysis writes the identification into the record
                // as soon as it exists: a record that holds it keeps it.
                let identified = match &read {
                    Ok(o) if e.data_complete => identified(&o.entries, &e.mcap),
                    _ => None,
                };
                (e.outcome, e.reason) = if let Some((outcome, reason, key_results)) = identified {
                    e.key_results = key_results;
                    (outcome, Some(reason))
                } else if e.data_complete {
                    (
                        RecordOutcome::Unanalysed,
                        Some(format!(
                            "the plan ended and its data is recorded, but the daemon stopped \
                             during the analysis; `motorbench replay {}` reruns it",
                            e.mcap
                        )),
                    )
                } else {
                    (
                        RecordOutcome::Interrupted,
                        Some("the daemon stopped during the test (killed or crashed)".into()),
                    )
                };
                e.recovered = Some(recovered_of(read));
                e.bytes = files_size(dir, e);
                interrupted.push(e.name.clone());
            }
        }
        let mut unknown: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(io_err(dir))?
            .filter_map(|d| d.ok().map(|d| d.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
            .filter(|p| {
                let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
                !index.entries.iter().any(|e| e.mcap == name)
            })
            .collect();
        unknown.sort();
        for p in unknown {
            let entry = entry_from_file(dir, &p);
            interrupted.push(entry.name.clone());
            index.entries.push(entry);
        }
        index
            .entries
            .sort_by(|a, b| a.started_unix_s.total_cmp(&b.started_unix_s));
        if !interrupted.is_empty() || !path.exists() {
            index.save()?;
        }
        Ok((index, interrupted))
    }

    /// The records directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Every entry, oldest first.
    pub fn entries(&self) -> &[IndexEntry] {
        &self.entries
    }

    /// The entry named `name`.
    pub fn get(&self, name: &str) -> Option<&IndexEntry> {
        self.entries.iter().find(|e| e.name == name)
    }

    /// Give rig-less entries (rebuilt from their files) to the rig whose
    /// motor they recorded, when exactly one of `rigs` (name, motor id)
    /// has that motor; saves when any changed. Returns the names adopted.
    pub fn adopt_orphans(&mut self, rigs: &[(String, String)]) -> Result<Vec<String>, IndexError> {
        let mut adopted = Vec::new();
        for e in self.entries.iter_mut().filter(|e| e.rig.is_empty()) {
            let mut owners = rigs.iter().filter(|(_, motor)| *motor == e.motor_id);
            if let (Some((rig, _)), None) = (owners.next(), owners.next()) {
                e.rig = rig.clone();
                adopted.push(e.name.clone());
            }
        }
        if !adopted.is_empty() {
            self.save()?;
        }
        Ok(adopted)
    }

    /// A record name from the motor id and the start time, used by no
    /// entry and no file.
    pub fn new_name(&self, motor_id: &str, started_at: &str) -> String {
        crate::session::record_name(motor_id, started_at, |s| {
            self.get(s).is_some()
                || ["mcap", "report.json", "svg", "residuals.svg"]
                    .iter()
                    .any(|x| self.dir.join(format!("{s}.{x}")).exists())
        })
    }

    /// Add an entry and save.
    pub fn insert(&mut self, entry: IndexEntry) -> Result<(), IndexError> {
        self.entries.retain(|e| e.name != entry.name);
        self.entries.push(entry);
        self.save()
    }

    /// Change the entry `name` (if there is one) and save.
    pub fn update(
        &mut self,
        name: &str,
        change: impl FnOnce(&mut IndexEntry),
    ) -> Result<(), IndexError> {
        if let Some(e) = self.entries.iter_mut().find(|e| e.name == name) {
            change(e);
            e.bytes = files_size(&self.dir, e);
        }
        self.save()
    }

    /// Write the index atomically. The entries are streamed into the
    /// file, neither copied nor first rendered into one string: the index
    /// grows with every test, and a save (three per test) would otherwise
    /// allocate about three times its size each time.
    pub fn save(&self) -> Result<(), IndexError> {
        let path = self.dir.join(INDEX_FILE);
        let tmp = self.dir.join(format!("{INDEX_FILE}.tmp"));
        let file = IndexFileRef {
            version: INDEX_VERSION,
            records: &self.entries,
        };
        let f = std::fs::File::create(&tmp).map_err(io_err(&tmp))?;
        let mut w = std::io::BufWriter::new(f);
        serde_json::to_writer_pretty(&mut w, &file).map_err(|e| IndexError::Io {
            path: tmp.display().to_string(),
            source: e.into(),
        })?;
        w.write_all(b"\n").map_err(io_err(&tmp))?;
        let f = w.into_inner().map_err(|e| io_err(&tmp)(e.into_error()))?;
        f.sync_all().map_err(io_err(&tmp))?;
        drop(f);
        std::fs::rename(&tmp, &path).map_err(io_err(&path))?;
        // The rename itself reaches the disk with the directory.
        if let Ok(d) = std::fs::File::open(&self.dir) {
            let _ = d.sync_all();
        }
        Ok(())
    }

    /// Delete `rig`'s oldest finished records until its records total at
    /// most `retention.max_total_bytes` and none is older than
    /// `retention.max_age_s`; running records are never deleted. Returns
    /// the names deleted.
    pub fn apply_retention(
        &mut self,
        rig: &str,
        retention: &Retention,
        now: SystemTime,
    ) -> Result<Vec<String>, IndexError> {
        let now_s = unix_s(now);
        let mut total: u64 = self
            .entries
            .iter()
            .filter(|e| e.rig == rig)
            .map(|e| e.bytes)
            .sum();
        let mut doomed = Vec::new();
        // Oldest first (the entries are kept in start order).
        for e in self.entries.iter().filter(|e| e.rig == rig) {
            if e.outcome == RecordOutcome::Running {
                continue;
            }
            let too_old = retention
                .max_age_s
                .is_some_and(|max| now_s - e.started_unix_s > max);
            if too_old || total > retention.max_total_bytes {
                total = total.saturating_sub(e.bytes);
                doomed.push(e.name.clone());
            }
        }
        for name in &doomed {
            let entry = self.get(name).expect("listed above").clone();
            for f in entry.files() {
                let p = self.dir.join(f);
                match std::fs::remove_file(&p) {
                    Ok(()) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                    Err(e) => return Err(io_err(&p)(e)),
                }
            }
            tracing::info!("retention: deleted record {name}");
            self.entries.retain(|e| &e.name != name);
        }
        if !doomed.is_empty() {
            self.save()?;
        }
        Ok(doomed)
    }
}

fn set_aside(path: &Path) -> Result<(), IndexError> {
    let aside = path.with_extension("json.corrupt");
    std::fs::rename(path, &aside).map_err(io_err(path))
}

fn files_size(dir: &Path, e: &IndexEntry) -> u64 {
    e.files()
        .iter()
        .filter_map(|f| std::fs::metadata(dir.join(f)).ok())
        .map(|m| m.len())
        .sum()
}

/// What the MCAP reader gets back from a (possibly truncated) record.
fn recover(path: &Path) -> Recovered {
    recovered_of(read_outline(path))
}

/// [`Recovered`] from what [`read_outline`] returned.
fn recovered_of(read: Result<Outline, crate::record::RecordError>) -> Recovered {
    match read {
        Ok(o) => {
            let messages = match &o.recovery {
                Some(r) => r.messages,
                None => o.samples + o.entries.len() as u64,
            };
            Recovered {
                messages,
                last_t_s: o.last_t_ns as f64 * 1e-9,
                damage: o.recovery.map(|r| r.reason),
            }
        }
        Err(e) => Recovered {
            messages: 0,
            last_t_s: 0.0,
            damage: Some(e.to_string()),
        },
    }
}

/// An entry for an MCAP file the index did not know (a new or a cut
/// index), rebuilt from the record itself: its metadata (motor, kind,
/// start), its `/bench/result` (key results: the file was finished), its
/// abort event. A whole file with a result is `completed` (`aborted` with
/// an abort event); an unfinished one is `interrupted`. The rig is left
/// empty here; [`RecordsIndex::adopt_orphans`] gives it one.
fn entry_from_file(dir: &Path, path: &Path) -> IndexEntry {
    let name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("unnamed")
        .to_string();
    let mcap = format!("{name}.mcap");
    let read = read_outline(path).ok();
    let meta = read.as_ref().map(|o| &o.meta);
    let modified = std::fs::metadata(path)
        .and_then(|m| m.modified())
        .unwrap_or(UNIX_EPOCH);
    let started_at = meta.map_or_else(
        || humantime::format_rfc3339_seconds(modified).to_string(),
        |m| m.started_at.clone(),
    );
    let started_unix_s = humantime::parse_rfc3339(&started_at)
        .map(unix_s)
        .unwrap_or_else(|_| unix_s(modified));
    let report = format!("{name}.report.json");
    let svg = format!("{name}.svg");
    let residuals_svg = format!("{name}.residuals.svg");
    let (outcome, reason, key_results) = match &read {
        Some(Outline {
            entries,
            recovery: None,
            ..
        }) => outcome_of(entries),
        _ => (
            RecordOutcome::Interrupted,
            Some("found in the records directory without an index entry".into()),
            None,
        ),
    };
    let recovered = (outcome == RecordOutcome::Interrupted).then(|| recover(path));
    let kind = meta.map_or_else(String::new, |m| m.kind.to_string());
    let mut e = IndexEntry {
        rig: String::new(),
        motor_id: meta.map_or_else(String::new, |m| m.motor_id.clone()),
        plan: kind.clone(),
        kind,
        started_at,
        started_unix_s,
        finished_at: None,
        outcome,
        reason,
        key_results,
        report: dir.join(&report).exists().then_some(report),
        svg: dir.join(&svg).exists().then_some(svg),
        residuals_svg: dir.join(&residuals_svg).exists().then_some(residuals_svg),
        mcap,
        bytes: 0,
        recovered,
        data_complete: false,
        name,
    };
    e.bytes = files_size(dir, &e);
    e
}

/// How a whole record ended, from its entries: its abort event, its
/// result and the result's headline parameters.
fn outcome_of(entries: &[Entry]) -> (RecordOutcome, Option<String>, Option<KeyResults>) {
    let abort = entries.iter().find_map(|e| match e {
        Entry::Event { event, .. } if event.level == EventLevel::Abort => {
            Some(event.message.clone())
        }
        _ => None,
    });
    let result = entries.iter().rev().find_map(|e| match e {
        Entry::Result { report, .. } => Some(report),
        _ => None,
    });
    let Some(report) = result else {
        return (
            RecordOutcome::Failed,
            Some("the record is whole but has no result".into()),
            None,
        );
    };
    let key_results = key_results_of(report);
    match abort {
        Some(reason) => (RecordOutcome::Aborted, Some(reason), key_results),
        None => (RecordOutcome::Completed, None, key_results),
    }
}

/// The outcome of a test whose daemon died during the analysis, when its
/// record already holds a `/bench/result` (the identification, written
/// before the diagnosis, or the whole report when only the report files
/// were still to write): `completed` or `aborted` as the record says, with
/// its key results and a reason saying what is missing. None when the
/// record holds no result.
fn identified(
    entries: &[Entry],
    mcap: &str,
) -> Option<(RecordOutcome, String, Option<KeyResults>)> {
    let report = entries.iter().rev().find_map(|e| match e {
        Entry::Result { report, .. } => Some(report),
        _ => None,
    })?;
    let (outcome, abort, key_results) = outcome_of(entries);
    let pending = report
        .get("diagnosis_pending")
        .and_then(serde_json::Value::as_bool)
        .unwrap_or(false);
    let note = if pending {
        format!(
            "the daemon stopped during the diagnosis: the record holds the identification, \
             not the diagnosis nor the report files; `motorbench replay {mcap}` reruns the analysis"
        )
    } else {
        format!(
            "the daemon stopped before writing the report files: the record holds the whole \
             result; `motorbench replay {mcap}` remakes the report"
        )
    };
    let reason = match abort {
        Some(abort) => format!("{abort}; {note}"),
        None => note,
    };
    Some((outcome, reason, key_results))
}

/// The best method's parameter values of a report (`best`, then
/// `methods[best].params[key].value`).
fn key_results_of(report: &serde_json::Value) -> Option<KeyResults> {
    let method = report.get("best")?.as_str()?.to_string();
    let params = report
        .get("methods")?
        .get(&method)?
        .get("params")?
        .as_object()?
        .iter()
        .filter_map(|(k, p)| Some((k.clone(), p.get("value")?.as_f64()?)))
        .collect();
    Some(KeyResults { method, params })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(name: &str, rig: &str, started_unix_s: f64, outcome: RecordOutcome) -> IndexEntry {
        IndexEntry {
            outcome,
            ..IndexEntry::running(
                name,
                rig,
                "m",
                "dc_step",
                "dc_step 60 → 248 V",
                "2026-11-21T10:00:00Z".into(),
                started_unix_s,
            )
        }
    }

    fn write(dir: &Path, name: &str, bytes: usize) {
        std::fs::write(dir.join(format!("{name}.mcap")), vec![0u8; bytes]).unwrap();
    }

    /// The work runs off the runtime's thread: on a current-thread
    /// runtime, a closure that waits for another task of that runtime
    /// would wait forever if it ran on the runtime's own thread.
    #[tokio::test(flavor = "current_thread")]
    async fn index_work_runs_off_the_runtime_thread() {
        let dir = tempfile::tempdir().unwrap();
        let (index, _) = RecordsIndex::open(dir.path()).unwrap();
        let index = Arc::new(tokio::sync::Mutex::new(index));
        let (tx, rx) = std::sync::mpsc::channel();
        let other = tokio::spawn(async move { tx.send(()).unwrap() });
        let saved = on_index(&index, move |idx| {
            let other_task_ran = rx.recv_timeout(std::time::Duration::from_secs(10)).is_ok();
            idx.insert(entry("a", "rig", 1.0, RecordOutcome::Completed))
                .unwrap();
            other_task_ran
        })
        .await;
        assert!(saved, "the runtime's other task did not run meanwhile");
        other.await.unwrap();
        assert!(index.lock().await.get("a").is_some());
        assert!(dir.path().join(INDEX_FILE).exists());
    }

    #[test]
    fn survives_a_restart_and_marks_running_records_interrupted() {
        let dir = tempfile::tempdir().unwrap();
        let (mut index, interrupted) = RecordsIndex::open(dir.path()).unwrap();
        assert!(interrupted.is_empty());
        write(dir.path(), "a", 10);
        write(dir.path(), "b", 20);
        index
            .insert(entry("a", "rig", 1.0, RecordOutcome::Completed))
            .unwrap();
        index
            .insert(entry("b", "rig", 2.0, RecordOutcome::Running))
            .unwrap();
        drop(index);
        assert!(!dir.path().join("index.json.tmp").exists());

        let (index, interrupted) = RecordsIndex::open(dir.path()).unwrap();
        assert_eq!(interrupted, ["b"]);
        let b = index.get("b").unwrap();
        assert_eq!(b.outcome, RecordOutcome::Interrupted);
        assert_eq!(b.bytes, 20);
        // Twenty zero bytes are no MCAP: nothing recovered, and it says why.
        let r = b.recovered.as_ref().unwrap();
        assert_eq!(r.messages, 0);
        assert!(r.damage.is_some());
        assert_eq!(index.get("a").unwrap().outcome, RecordOutcome::Completed);
        // Marked once: the next open finds nothing new.
        drop(index);
        let (_, again) = RecordsIndex::open(dir.path()).unwrap();
        assert!(again.is_empty());
    }

    /// A record with samples and, when `result`, the identification as a
    /// `/bench/result` marked `diagnosis_pending`; cut (no summary, as a
    /// killed writer leaves it) when `cut`, keeping the result.
    fn record(path: &Path, result: bool, cut: bool) {
        use crate::record::{ChannelSpec, Recorder, SegmentKind, TestMeta, SCHEMA_VERSION};
        let meta = TestMeta {
            schema_version: SCHEMA_VERSION.into(),
            kind: SegmentKind::DcStep,
            motor_id: "m".into(),
            started_at: "2026-11-21T10:00:00Z".into(),
            nameplate: serde_json::json!({}),
            config: String::new(),
        };
        let channels = [ChannelSpec::sensor("armature_voltage", "V", "daq0")];
        let mut entries: Vec<Entry> = (0..100u64)
            .map(|k| Entry::Samples {
                t_ns: k * 1_000_000,
                values: vec![(0, 12.0)],
            })
            .collect();
        if result {
            entries.push(Entry::Result {
                t_ns: 100_000_000,
                report: serde_json::json!({"best": "steady_state", "diagnosis_pending": true,
                    "methods": {"steady_state": {"params": {"K": {"value": 1.3}}}}}),
            });
        }
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        rt.block_on(async {
            let rec = Recorder::start(path, &meta, &channels, 64).unwrap();
            for e in entries {
                rec.send(e).await.unwrap();
            }
            rec.finish().await.unwrap();
        });
        if cut {
            // The longest cut of the file that no longer reads whole: the
            // summary gone, the chunks (and the result) kept.
            let bytes = std::fs::read(path).unwrap();
            let n = (1..bytes.len())
                .rev()
                .find(|&n| {
                    std::fs::write(path, &bytes[..n]).unwrap();
                    matches!(
                        read_outline(path),
                        Ok(Outline {
                            recovery: Some(_),
                            ..
                        })
                    )
                })
                .unwrap();
            std::fs::write(path, &bytes[..n]).unwrap();
        }
    }

    #[test]
    fn a_record_holding_its_identification_is_not_marked_unanalysed() {
        let dir = tempfile::tempdir().unwrap();
        let (mut index, _) = RecordsIndex::open(dir.path()).unwrap();
        // Killed during the diagnosis (the record cut, the identification
        // in it); killed before the report files (the record whole);
        // killed before the identification; killed during the plan.
        for (name, result, cut, data_complete) in [
            ("diagnosing", true, true, true),
            ("reporting", true, false, true),
            ("identifying", false, true, true),
            ("running", false, true, false),
        ] {
            record(&dir.path().join(format!("{name}.mcap")), result, cut);
            let mut e = entry(name, "rig", 1.0, RecordOutcome::Running);
            e.data_complete = data_complete;
            index.insert(e).unwrap();
        }
        drop(index);
        let (index, marked) = RecordsIndex::open(dir.path()).unwrap();
        assert_eq!(marked.len(), 4);
        let k = |name: &str| index.get(name).unwrap().key_results.clone();
        let diagnosing = index.get("diagnosing").unwrap();
        assert_eq!(diagnosing.outcome, RecordOutcome::Completed);
        assert_eq!(k("diagnosing").unwrap().params["K"], 1.3);
        let why = diagnosing.reason.as_deref().unwrap();
        assert!(why.contains("during the diagnosis"), "{why}");
        assert!(diagnosing.recovered.as_ref().unwrap().damage.is_some());
        let reporting = index.get("reporting").unwrap();
        assert_eq!(reporting.outcome, RecordOutcome::Completed);
        assert!(reporting
            .reason
            .as_deref()
            .unwrap()
            .contains("report files"));
        assert!(reporting.recovered.as_ref().unwrap().damage.is_none());
        assert_eq!(k("reporting").unwrap().method, "steady_state");
        let identifying = index.get("identifying").unwrap();
        assert_eq!(identifying.outcome, RecordOutcome::Unanalysed);
        assert!(k("identifying").is_none());
        assert_eq!(
            index.get("running").unwrap().outcome,
            RecordOutcome::Interrupted
        );
    }

    #[test]
    fn unknown_files_are_indexed_and_a_corrupt_index_is_rebuilt() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "stray", 5);
        std::fs::write(dir.path().join(INDEX_FILE), "{ not json").unwrap();
        let (index, found) = RecordsIndex::open(dir.path()).unwrap();
        assert_eq!(found, ["stray"]);
        assert_eq!(
            index.get("stray").unwrap().outcome,
            RecordOutcome::Interrupted
        );
        assert!(dir.path().join("index.json.corrupt").exists());
        let text = std::fs::read_to_string(dir.path().join(INDEX_FILE)).unwrap();
        assert!(text.contains("\"stray\""));
    }

    #[test]
    fn retention_deletes_the_oldest_finished_records_first() {
        let dir = tempfile::tempdir().unwrap();
        let (mut index, _) = RecordsIndex::open(dir.path()).unwrap();
        for (k, name) in ["r1", "r2", "r3", "r4"].iter().enumerate() {
            write(dir.path(), name, 100);
            let outcome = if k == 0 {
                RecordOutcome::Running
            } else {
                RecordOutcome::Completed
            };
            index.insert(entry(name, "rig", k as f64, outcome)).unwrap();
            index.update(name, |_| {}).unwrap();
        }
        write(dir.path(), "other", 1000);
        index
            .insert(entry("other", "rig2", 0.0, RecordOutcome::Completed))
            .unwrap();
        index.update("other", |_| {}).unwrap();
        let keep_250 = Retention {
            max_total_bytes: 250,
            max_age_s: None,
        };
        let now = UNIX_EPOCH + std::time::Duration::from_secs(10);
        let gone = index.apply_retention("rig", &keep_250, now).unwrap();
        // r1 is running (kept though oldest); r2 and r3 go; 200 B remain.
        assert_eq!(gone, ["r2", "r3"]);
        assert!(!dir.path().join("r2.mcap").exists());
        assert!(dir.path().join("r1.mcap").exists() && dir.path().join("other.mcap").exists());
        let by_age = Retention {
            max_total_bytes: u64::MAX,
            max_age_s: Some(5.0),
        };
        let now = UNIX_EPOCH + std::time::Duration::from_secs(8);
        // r4 started at 3 s: 5 s old, not older than 5 s: kept.
        assert!(index
            .apply_retention("rig", &by_age, now)
            .unwrap()
            .is_empty());
        let now = UNIX_EPOCH + std::time::Duration::from_secs(9);
        assert_eq!(index.apply_retention("rig", &by_age, now).unwrap(), ["r4"]);
        let (reopened, _) = RecordsIndex::open(dir.path()).unwrap();
        let names: Vec<_> = reopened.entries().iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["r1", "other"]);
    }

    #[test]
    fn names_are_unique_and_safe() {
        let dir = tempfile::tempdir().unwrap();
        let (mut index, _) = RecordsIndex::open(dir.path()).unwrap();
        let a = index.new_name("motor 7/a", "2026-11-21T10:00:00Z");
        assert_eq!(a, "motor_7_a-20261121T100000Z");
        index
            .insert(entry(&a, "rig", 0.0, RecordOutcome::Completed))
            .unwrap();
        assert_eq!(
            index.new_name("motor 7/a", "2026-11-21T10:00:00Z"),
            "motor_7_a-20261121T100000Z-2"
        );
    }
}
