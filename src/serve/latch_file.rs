//! The rigs' latched stops kept on disk (`latches.json` beside the
//! records index), so that a daemon that restarts — after a crash, a kill
//! or a reboot — does not forget a trip the operator has not yet
//! acknowledged. A rig latched before the restart stays latched until
//! `motorbench ctl reset`.
//!
//! Written atomically (a temporary file, synced, renamed over the old
//! one) every time a latch is set or cleared. A file that cannot be read
//! is not taken as "nothing latched": every rig is latched with a message
//! that says why, the cautious reading of a lost record.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::state::Latch;

/// The file's name in the records directory.
pub const LATCH_FILE: &str = "latches.json";

/// The latches file of one records directory.
#[derive(Debug, Clone)]
pub struct LatchFile {
    path: PathBuf,
}

#[derive(Serialize, Deserialize)]
struct Contents {
    /// Latched rigs by name.
    latched: BTreeMap<String, Latch>,
}

impl LatchFile {
    /// The latches file in `records`.
    pub fn new(records: &Path) -> LatchFile {
        LatchFile {
            path: records.join(LATCH_FILE),
        }
    }

    /// The latches kept for `rigs`: none when the file does not exist;
    /// every rig latched, saying why, when it cannot be read. Latches of
    /// rigs no longer configured are dropped with a log line.
    pub fn load(&self, rigs: &[String]) -> BTreeMap<String, Latch> {
        let text = match std::fs::read_to_string(&self.path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return BTreeMap::new(),
            Err(e) => return self.all_latched(rigs, &e.to_string()),
        };
        let mut latched = match serde_json::from_str::<Contents>(&text) {
            Ok(c) => c.latched,
            Err(e) => return self.all_latched(rigs, &e.to_string()),
        };
        latched.retain(|rig, latch| {
            let known = rigs.contains(rig);
            if !known {
                tracing::warn!(
                    "{}: rig `{rig}` is no longer configured; its latch ({}) is dropped",
                    self.path.display(),
                    latch.message
                );
            }
            known
        });
        latched
    }

    fn all_latched(&self, rigs: &[String], why: &str) -> BTreeMap<String, Latch> {
        let message = format!(
            "the latched stops kept in {} cannot be read ({why}): every rig is latched \
             until an operator has checked it and reset it",
            self.path.display()
        );
        tracing::error!("{message}");
        rigs.iter()
            .map(|r| {
                (
                    r.clone(),
                    Latch {
                        kind: "latch_file_unreadable".into(),
                        message: message.clone(),
                        at: super::state::now_rfc3339(),
                    },
                )
            })
            .collect()
    }

    /// Write `latched` (atomically: a synced temporary file renamed over
    /// the old one).
    pub fn save(&self, latched: &BTreeMap<String, Latch>) -> std::io::Result<()> {
        let tmp = self.path.with_extension("json.tmp");
        let mut f = std::fs::File::create(&tmp)?;
        serde_json::to_writer_pretty(
            &mut f,
            &Contents {
                latched: latched.clone(),
            },
        )?;
        f.write_all(b"\n")?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, &self.path)?;
        if let Some(dir) = self.path.parent() {
            if let Ok(d) = std::fs::File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }
}

/// The latches in memory and on disk together: every change is written
/// through to the file.
#[derive(Debug)]
pub struct LatchStore {
    file: LatchFile,
    latched: std::sync::Mutex<BTreeMap<String, Latch>>,
}

impl LatchStore {
    /// The store of `records`, with the latches kept for `rigs` loaded.
    pub fn open(records: &Path, rigs: &[String]) -> LatchStore {
        let file = LatchFile::new(records);
        let latched = std::sync::Mutex::new(file.load(rigs));
        LatchStore { file, latched }
    }

    /// The latch kept for `rig`.
    pub fn get(&self, rig: &str) -> Option<Latch> {
        self.lock().get(rig).cloned()
    }

    /// Set (`Some`) or clear (`None`) `rig`'s latch and write the file. A
    /// write that fails is logged: the latch holds in memory regardless.
    pub fn set(&self, rig: &str, latch: Option<Latch>) {
        let mut latched = self.lock();
        match latch {
            Some(l) => latched.insert(rig.to_string(), l),
            None => latched.remove(rig),
        };
        if let Err(e) = self.file.save(&latched) {
            tracing::error!(
                "the latched stops could not be written to {}: {e}; a restart would forget them",
                self.file.path.display()
            );
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, BTreeMap<String, Latch>> {
        self.latched.lock().unwrap_or_else(|p| p.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn latch(kind: &str) -> Latch {
        Latch {
            kind: kind.into(),
            message: format!("{kind} on the bench"),
            at: "2026-12-04T16:00:00Z".into(),
        }
    }

    #[test]
    fn latches_survive_a_save_and_load_and_unknown_rigs_are_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let file = LatchFile::new(dir.path());
        let rigs = vec!["dc".to_string(), "im".to_string()];
        assert!(file.load(&rigs).is_empty(), "no file: nothing latched");
        let mut latched = BTreeMap::new();
        latched.insert("dc".to_string(), latch("limit"));
        latched.insert("gone".to_string(), latch("emergency_stop"));
        file.save(&latched).unwrap();
        let back = file.load(&rigs);
        assert_eq!(back.len(), 1);
        assert_eq!(back["dc"], latch("limit"));
        assert!(!dir.path().join("latches.json.tmp").exists());
    }

    #[test]
    fn the_store_writes_every_change_through() {
        let dir = tempfile::tempdir().unwrap();
        let rigs = vec!["dc".to_string()];
        let store = LatchStore::open(dir.path(), &rigs);
        store.set("dc", Some(latch("limit")));
        assert_eq!(
            LatchStore::open(dir.path(), &rigs).get("dc"),
            Some(latch("limit"))
        );
        store.set("dc", None);
        assert_eq!(LatchStore::open(dir.path(), &rigs).get("dc"), None);
    }

    #[test]
    fn an_unreadable_file_latches_every_rig() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(LATCH_FILE), "{ not json").unwrap();
        let rigs = vec!["dc".to_string(), "im".to_string()];
        let back = LatchFile::new(dir.path()).load(&rigs);
        assert_eq!(back.len(), 2);
        assert!(back
            .values()
            .all(|l| l.kind == "latch_file_unreadable" && l.message.contains("cannot be read")));
    }
}
