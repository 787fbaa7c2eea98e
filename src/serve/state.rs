//! The daemon's state: its rigs (one test at a time each, a latched trip,
//! the winding-temperature memory between tests), the records index, and
//! the tests this process has run. The API handlers call into it.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex as StdMutex};
use std::time::SystemTime;

use serde::{Deserialize, Serialize};
use tokio::sync::Mutex;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::jobs::{prepare, SetupError, StopStatus, TestRun};
use super::latch_file::LatchStore;
use super::metrics::Metrics;
use super::records_index::{IndexError, RecordsIndex};
use super::rig_config::RigConfig;
use crate::bench::{StopCause, StopReport};

/// A latched stop: the rig refuses new tests until an operator resets it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Latch {
    /// Machine-readable cause (`emergency_stop`, `limit`, …).
    pub kind: String,
    /// For a person.
    pub message: String,
    /// When, RFC 3339.
    pub at: String,
}

impl Latch {
    fn from_report(r: &StopReport) -> Latch {
        Latch {
            kind: r.cause.kind().to_string(),
            message: r.describe(),
            at: now_rfc3339(),
        }
    }
}

pub(super) fn now_rfc3339() -> String {
    humantime::format_rfc3339_seconds(SystemTime::now()).to_string()
}

/// What changes on a rig while the daemon runs.
#[derive(Debug)]
struct RigRuntime {
    running: Option<Arc<TestRun>>,
    latch: Option<Latch>,
    /// Winding rise above ambient at `winding_at`, K.
    winding_rise_k: f64,
    winding_at: Instant,
}

/// One rig the daemon drives.
#[derive(Debug)]
pub struct Rig {
    /// Name (the configuration file's stem).
    pub name: String,
    /// Its configuration.
    pub cfg: RigConfig,
    runtime: Mutex<RigRuntime>,
}

impl Rig {
    /// The winding rise now, cooled since the last test, K.
    fn rise_now(rt: &RigRuntime, cfg: &RigConfig) -> f64 {
        let tau = cfg.common().supervision.thermal.time_constant;
        rt.winding_rise_k * (-rt.winding_at.elapsed().as_secs_f64() / tau).exp()
    }
}

/// A rig's state as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct RigStatus {
    /// Rig name.
    pub name: String,
    /// Motor under test.
    pub motor_id: String,
    /// Backend kind.
    pub backend: String,
    /// The machine: `dc` or `induction`.
    pub machine: String,
    /// The stages the supervisor commands safe on a stop, in order.
    pub stages: Vec<String>,
    /// Configuration file.
    pub config: String,
    /// `idle`, `running` or `tripped`.
    pub state: String,
    /// The running test's id.
    pub running_test: Option<String>,
    /// The latched stop, when tripped.
    pub trip: Option<Latch>,
    /// Estimated winding temperature now, °C.
    pub winding_c: f64,
}

/// Why a test could not start.
#[derive(Debug)]
pub enum StartError {
    /// No rig of that name.
    NoSuchRig(String),
    /// The rig runs a test already.
    Busy {
        /// Its id.
        running: String,
    },
    /// The rig is latched after a stop.
    Tripped(Latch),
    /// The daemon is shutting down.
    Stopping,
    /// The request's override is invalid.
    BadRequest(String),
    /// The rig or the record could not be set up.
    Setup(SetupError),
}

/// Why a stop request failed.
#[derive(Debug)]
pub enum StopError {
    /// Unknown test or rig.
    NotFound(String),
    /// The test is not running.
    NotRunning(String),
}

/// The daemon. See the module docs.
#[derive(Debug)]
pub struct Daemon {
    rigs: BTreeMap<String, Arc<Rig>>,
    index: Arc<Mutex<RecordsIndex>>,
    tests: StdMutex<BTreeMap<String, Arc<TestRun>>>,
    jobs: StdMutex<Vec<JoinHandle<()>>>,
    stopping: AtomicBool,
    metrics: Arc<Metrics>,
    /// The latches as kept on disk (`latches.json`): a restart keeps them.
    latches: Arc<LatchStore>,
}

/// Finished tests the daemon keeps in memory (`GET /v1/tests`, `GET
/// /v1/tests/{id}`), the most recent ones; older tests are in the records
/// index (`GET /v1/records`) only. Unbounded, the list grew the daemon by
/// several kB a test.
pub const KEEP_FINISHED_TESTS: usize = 100;

/// Drop the oldest (smallest id: ids sort by start time) finished entries
/// of `tests` until at most `keep` finished ones are left; running ones
/// always stay.
fn prune_oldest_finished<V>(
    tests: &mut BTreeMap<String, V>,
    keep: usize,
    finished: impl Fn(&V) -> bool,
) {
    let done = tests.values().filter(|v| finished(v)).count();
    let drop: Vec<String> = tests
        .iter()
        .filter(|(_, v)| finished(v))
        .take(done.saturating_sub(keep))
        .map(|(k, _)| k.clone())
        .collect();
    for k in drop {
        tests.remove(&k);
    }
}

fn lock<T>(m: &StdMutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Daemon {
    /// A daemon over `rigs` (name, configuration) recording into `records`.
    /// Opening the index marks records left `running` as interrupted.
    pub fn new(rigs: Vec<(String, RigConfig)>, records: &Path) -> Result<Daemon, IndexError> {
        let (mut index, interrupted) = RecordsIndex::open(records)?;
        for name in &interrupted {
            if let Some(e) = index.get(name) {
                tracing::warn!(
                    "record {name} is {} ({}); recovered: {:?}",
                    serde_json::to_string(&e.outcome).unwrap_or_default(),
                    e.reason.as_deref().unwrap_or(""),
                    e.recovered
                );
            }
        }
        let owners: Vec<(String, String)> = rigs
            .iter()
            .map(|(name, cfg)| (name.clone(), cfg.common().motor_id.clone()))
            .collect();
        for name in index.adopt_orphans(&owners)? {
            let rig = index.get(&name).map_or("", |e| e.rig.as_str());
            tracing::info!("record {name} rebuilt from its file belongs to rig {rig} (its motor)");
        }
        for (name, cfg) in &rigs {
            index.apply_retention(name, &cfg.common().retention, SystemTime::now())?;
        }
        let names: Vec<String> = rigs.iter().map(|(n, _)| n.clone()).collect();
        let latches = Arc::new(LatchStore::open(records, &names));
        let rigs = rigs
            .into_iter()
            .map(|(name, cfg)| {
                let rig = Rig {
                    name: name.clone(),
                    cfg,
                    runtime: Mutex::new(RigRuntime {
                        running: None,
                        latch: latches.get(&name).inspect(|l| {
                            tracing::warn!(
                                "rig {name}: still latched from before the restart ({}); \
                                 `motorbench ctl reset` clears it",
                                l.message
                            )
                        }),
                        winding_rise_k: 0.0,
                        winding_at: Instant::now(),
                    }),
                };
                (name, Arc::new(rig))
            })
            .collect();
        Ok(Daemon {
            rigs,
            index: Arc::new(Mutex::new(index)),
            tests: StdMutex::new(BTreeMap::new()),
            jobs: StdMutex::new(Vec::new()),
            stopping: AtomicBool::new(false),
            metrics: Arc::new(Metrics::new()),
            latches,
        })
    }

    /// The records index.
    pub fn index(&self) -> &Arc<Mutex<RecordsIndex>> {
        &self.index
    }

    /// The daemon's metrics.
    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }

    /// Rig names.
    pub fn rig_names(&self) -> Vec<String> {
        self.rigs.keys().cloned().collect()
    }

    /// The status of every rig.
    pub async fn rigs(&self) -> Vec<RigStatus> {
        let mut out = Vec::new();
        for rig in self.rigs.values() {
            out.push(self.rig_status(rig).await);
        }
        out
    }

    /// The status of rig `name`.
    pub async fn rig(&self, name: &str) -> Option<RigStatus> {
        let rig = self.rigs.get(name)?;
        Some(self.rig_status(rig).await)
    }

    async fn rig_status(&self, rig: &Rig) -> RigStatus {
        let rt = rig.runtime.lock().await;
        let running = rt.running.as_ref().filter(|r| !r.finished());
        let state = match (&running, &rt.latch) {
            (Some(_), _) => "running",
            (None, Some(_)) => "tripped",
            (None, None) => "idle",
        };
        let winding_c = match running {
            Some(r) => r.status().values.winding_c,
            None => rig.cfg.common().supervision.thermal.ambient + Rig::rise_now(&rt, &rig.cfg),
        };
        RigStatus {
            name: rig.name.clone(),
            motor_id: rig.cfg.common().motor_id.clone(),
            backend: rig.cfg.describe(),
            machine: rig.cfg.machine().to_string(),
            stages: rig.cfg.stages().iter().map(|s| s.to_string()).collect(),
            config: rig.cfg.common().source.clone(),
            state: state.into(),
            running_test: running.map(|r| r.id()),
            trip: rt.latch.clone(),
            winding_c,
        }
    }

    /// The test `id` run by this process (while running, and among the
    /// last [`KEEP_FINISHED_TESTS`] finished).
    pub fn test(&self, id: &str) -> Option<Arc<TestRun>> {
        lock(&self.tests).get(id).cloned()
    }

    /// The tests run by this process, oldest first: the running ones and
    /// the last [`KEEP_FINISHED_TESTS`] finished.
    pub fn tests(&self) -> Vec<Arc<TestRun>> {
        lock(&self.tests).values().cloned().collect()
    }

    /// Start a test on `rig`: the configured plan, with `test` (keys of
    /// `[test]`) applied over it when given.
    pub async fn start(
        self: &Arc<Self>,
        rig_name: &str,
        test: Option<&serde_json::Map<String, serde_json::Value>>,
    ) -> Result<Arc<TestRun>, StartError> {
        let rig = self
            .rigs
            .get(rig_name)
            .cloned()
            .ok_or_else(|| StartError::NoSuchRig(rig_name.to_string()))?;
        let mut rt = rig.runtime.lock().await;
        if self.stopping.load(Ordering::SeqCst) {
            return Err(StartError::Stopping);
        }
        if let Some(r) = rt.running.as_ref().filter(|r| !r.finished()) {
            return Err(StartError::Busy { running: r.id() });
        }
        if let Some(latch) = &rt.latch {
            return Err(StartError::Tripped(latch.clone()));
        }
        let cfg = match test {
            Some(t) => rig
                .cfg
                .with_test(t)
                .map_err(|e| StartError::BadRequest(e.to_string()))?,
            None => rig.cfg.clone(),
        };
        let rise = Rig::rise_now(&rt, &rig.cfg);
        let (run, job) = prepare(
            rig_name,
            cfg.into_machine(),
            rise,
            self.index.clone(),
            self.metrics.clone(),
        )
        .await
        .map_err(StartError::Setup)?;
        let id = run.id();
        tracing::info!(
            "{id}: test started on rig {rig_name} ({})",
            run.status().plan
        );
        rt.running = Some(run.clone());
        {
            let mut tests = lock(&self.tests);
            tests.insert(id, run.clone());
            // A long-running daemon keeps the recent finished tests in
            // memory; every test's record and outcome stay in the index.
            prune_oldest_finished(&mut tests, KEEP_FINISHED_TESTS, |t| t.finished());
        }
        drop(rt);
        self.metrics.test_started(rig_name);
        let rig = rig.clone();
        let latches = self.latches.clone();
        let handle = tokio::spawn(async move {
            // The rig learns how the run ended as soon as it is safe,
            // before the analysis: its test cannot be seen finished while
            // a latching stop is not latched yet.
            job.run(|end| async move {
                let mut rt = rig.runtime.lock().await;
                rt.winding_rise_k = end.winding_rise_k;
                rt.winding_at = Instant::now();
                if let Some(stop) = &end.latch {
                    if rt.latch.is_none() {
                        let latch = Latch::from_report(stop);
                        latches.set(&rig.name, Some(latch.clone()));
                        rt.latch = Some(latch);
                    }
                }
            })
            .await;
            // The analysis' memory is free now: hand it back, so that the
            // daemon's resident size follows its live heap.
            super::heap::release_freed_memory().await;
        });
        let mut jobs = lock(&self.jobs);
        jobs.retain(|j| !j.is_finished());
        jobs.push(handle);
        Ok(run)
    }

    /// Abort test `id`: the safe state first; returns what the supervisor
    /// did.
    pub async fn abort(&self, id: &str) -> Result<StopStatus, StopError> {
        let run = self
            .test(id)
            .ok_or_else(|| StopError::NotFound(format!("no test `{id}`")))?;
        if run.finished() {
            return Err(StopError::NotRunning(format!("test `{id}` has finished")));
        }
        let report = run
            .stop(StopCause::OperatorAbort)
            .await
            .ok_or_else(|| StopError::NotRunning(format!("test `{id}` is ending")))?;
        Ok(StopStatus::from(&report))
    }

    /// Emergency stop on `rig`: a running test is stopped (safe state
    /// first) and the rig latches until [`Daemon::reset`].
    pub async fn emergency_stop(
        &self,
        rig_name: &str,
        source: &str,
    ) -> Result<RigStatus, StopError> {
        let rig = self
            .rigs
            .get(rig_name)
            .ok_or_else(|| StopError::NotFound(format!("no rig `{rig_name}`")))?;
        let running = rig.runtime.lock().await.running.clone();
        let cause = StopCause::EmergencyStop {
            source: source.to_string(),
        };
        self.metrics.emergency_stop(rig_name, source);
        let latch = match running.filter(|r| !r.finished()) {
            Some(run) => match run.stop(cause.clone()).await {
                Some(report) => Latch::from_report(&report),
                None => Latch {
                    kind: cause.kind().into(),
                    message: cause.to_string(),
                    at: now_rfc3339(),
                },
            },
            None => Latch {
                kind: cause.kind().into(),
                message: format!("{cause} while idle"),
                at: now_rfc3339(),
            },
        };
        tracing::warn!("rig {rig_name}: {}", latch.message);
        // The latch set here wins over the job's own: the operator's stop
        // is what must be acknowledged.
        self.latches.set(rig_name, Some(latch.clone()));
        rig.runtime.lock().await.latch = Some(latch);
        Ok(self.rig_status(rig).await)
    }

    /// Clear a latched stop on `rig`.
    pub async fn reset(&self, rig_name: &str) -> Result<RigStatus, StopError> {
        let rig = self
            .rigs
            .get(rig_name)
            .ok_or_else(|| StopError::NotFound(format!("no rig `{rig_name}`")))?;
        let mut rt = rig.runtime.lock().await;
        if rt.running.as_ref().is_some_and(|r| !r.finished()) {
            return Err(StopError::NotRunning(
                "a test is still ending on this rig; reset after it has finished".into(),
            ));
        }
        if let Some(l) = rt.latch.take() {
            self.latches.set(rig_name, None);
            tracing::info!("rig {rig_name}: reset by the operator (was: {})", l.message);
        }
        drop(rt);
        Ok(self.rig_status(rig).await)
    }

    /// True while every running test's supervisor is healthy.
    pub fn healthy(&self) -> bool {
        lock(&self.tests).values().all(|t| t.healthy())
    }

    /// Refuse new tests, stop the running ones (safe state first), and
    /// wait until their records are finished and indexed.
    pub async fn shutdown(&self) {
        self.stopping.store(true, Ordering::SeqCst);
        for run in self.tests() {
            if !run.finished() {
                // The supervisor logs what it did.
                let _ = run.stop(StopCause::Shutdown).await;
            }
        }
        let jobs: Vec<JoinHandle<()>> = std::mem::take(&mut *lock(&self.jobs));
        for j in jobs {
            let _ = j.await;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A test stopped by a latching fault (a NaN current) on the
    /// simulated DC rig: the moment its status says `finished`, the rig is
    /// `tripped` and refuses the next test. The latch used to be set after
    /// the status was published, which left a window in which the rig
    /// read `idle` and would start a new test.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_latching_stop_is_latched_before_its_test_is_seen_finished() {
        let dir = tempfile::tempdir().unwrap();
        let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-dc.toml");
        let text = std::fs::read_to_string(shipped).unwrap()
            + "\n[[fault]]\nkind = \"nan\"\nat_s = 0.3\ntarget = \"armature_current\"\n";
        let config = dir.path().join("rig.toml");
        std::fs::write(&config, text).unwrap();
        let rigs = crate::serve::load_rigs(&[config]).unwrap();
        let daemon = Arc::new(Daemon::new(rigs, &dir.path().join("records")).unwrap());
        let test = serde_json::json!({"levels_V": [60, 248], "coastdown": false});
        let run = daemon
            .start("rig", test.as_object())
            .await
            .expect("the test starts");
        run.wait_finished().await;
        let rig = daemon.rig("rig").await.unwrap();
        assert_eq!(rig.state, "tripped", "{:?}", run.status().stop);
        assert!(
            matches!(daemon.start("rig", None).await, Err(StartError::Tripped(_))),
            "a tripped rig refuses the next test"
        );
        daemon.shutdown().await;
    }

    #[test]
    fn only_the_newest_finished_tests_are_kept_and_running_ones_stay() {
        let mut tests: BTreeMap<String, bool> = (0..10)
            .map(|i| (format!("t{i:02}"), i != 1 && i != 8))
            .collect();
        prune_oldest_finished(&mut tests, 3, |f| *f);
        let left: Vec<&str> = tests.keys().map(String::as_str).collect();
        // Eight finished (t00, t02–t07, t09): the three newest stay, and
        // the running t01 and t08 however old.
        assert_eq!(
            left,
            ["t01", "t06", "t07", "t08", "t09"],
            "running t01 and t08 stay"
        );
        prune_oldest_finished(&mut tests, 3, |f| *f);
        assert_eq!(tests.len(), 5, "nothing more to drop");
    }
}
