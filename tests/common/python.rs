//! The Python interpreter the tests run their peers and readers with
//! (tests/python/*.py need the packages of tests/python/requirements.txt).
//!
//! `tests/run.sh` installs those packages into a virtual environment,
//! `target/test-venv`, and names its interpreter in `MOTORBENCH_PYTHON`; a
//! stock Debian python refuses a bare `pip install`, so the packages are
//! never installed system-wide. A test run without the variable uses that
//! environment when an earlier `tests/run.sh` made it, else `python3`. A
//! missing interpreter or package fails the test with what to do, it is
//! never skipped.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The variable naming the interpreter (set by `tests/run.sh`).
pub const VAR: &str = "MOTORBENCH_PYTHON";

/// The modules tests/python/*.py import, one per requirement.
const MODULES: &str =
    "import mcap, pymodbus, serial, can, jsonschema, prometheus_client, websockets";

/// The interpreter, checked once per test process to import every
/// required package; panics naming the interpreter and the fix when not.
pub fn interpreter() -> &'static Path {
    static PYTHON: OnceLock<PathBuf> = OnceLock::new();
    PYTHON.get_or_init(|| {
        let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-venv/bin/python3");
        let python = match std::env::var_os(VAR) {
            Some(p) => PathBuf::from(p),
            None if venv.exists() => venv,
            None => PathBuf::from("python3"),
        };
        let fix = format!(
            "run tests/run.sh (it creates target/test-venv with \
             tests/python/requirements.txt), or set {VAR} to a python that has them"
        );
        let out = Command::new(&python)
            .args(["-c", MODULES])
            .output()
            .unwrap_or_else(|e| panic!("cannot run {}: {e}; {fix}", python.display()));
        assert!(
            out.status.success(),
            "{} lacks the Python test packages ({}); {fix}",
            python.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
        python
    })
}
