//! A shipped configuration run, its record found and replayed: the
//! report of `motorbench run --json`, the one MCAP file it wrote to its
//! output directory, and `motorbench replay --check` of it.

use std::path::{Path, PathBuf};

use super::{motorbench, text};

/// `motorbench run --config CONFIG --out DIR --json` with `extra`
/// arguments, `CONFIG` a file of the repository's `config/`: it must
/// succeed; the report it prints.
pub fn run_json(config: &str, dir: &Path, extra: &[&str]) -> serde_json::Value {
    let config = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(config);
    let mut args = vec![
        "run",
        "--config",
        config.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
        "--json",
    ];
    args.extend(extra);
    let out = motorbench(&args);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    serde_json::from_str(&stdout).unwrap()
}

/// The one MCAP record in `dir`; panics unless there is exactly one.
pub fn only_mcap(dir: &Path) -> PathBuf {
    let mcap: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    assert_eq!(mcap.len(), 1, "{mcap:?}");
    mcap.into_iter().next().unwrap()
}

/// `motorbench replay MCAP --check --json` with `extra` arguments: it
/// must succeed and find its report identical to the recorded one; the
/// report it prints.
pub fn replay_identical(mcap: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["replay", mcap.to_str().unwrap(), "--check", "--json"];
    args.extend(extra);
    let out = motorbench(&args);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("identical to the recorded /bench/result"),
        "{stderr}"
    );
    serde_json::from_str(&stdout).unwrap()
}
