//! The systemd unit passes `systemd-analyze verify`, keeps the settings
//! the daemon relies on, and its `systemd-analyze security` exposure stays
//! low. `tests/run.sh` installs systemd's tools where they are missing; a
//! missing `systemd-analyze` fails this test, it never skips it.

use std::path::Path;
use std::process::Command;

const UNIT: &str = include_str!("../../systemd/motorbench.service");

/// The unit with `ExecStart=` pointing at the binary under test (verify
/// checks that the command exists), written to a temporary directory.
fn unit_for_this_build() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("motorbench.service");
    let text = UNIT.replace(
        "/usr/local/bin/motorbench",
        env!("CARGO_BIN_EXE_motorbench"),
    );
    assert_ne!(text, UNIT, "the unit starts /usr/local/bin/motorbench");
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

fn systemd_analyze(args: &[&str], unit: &Path) -> std::process::Output {
    Command::new("systemd-analyze")
        .args(args)
        .arg(unit)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "systemd-analyze cannot run ({e}); install systemd (`apt-get install -y systemd`; tests/run.sh does)"
            )
        })
}

#[test]
fn unit_passes_systemd_analyze_verify() {
    let (_dir, unit) = unit_for_this_build();
    let out = systemd_analyze(&["verify"], &unit);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "systemd-analyze verify failed:\n{stderr}"
    );
    assert!(
        stderr.trim().is_empty(),
        "systemd-analyze verify warned:\n{stderr}"
    );
}

#[test]
fn unit_keeps_what_the_daemon_relies_on() {
    for line in [
        "Type=notify",
        "WatchdogSec=",
        "User=motorbench",
        "ProtectSystem=strict",
        "PrivateTmp=yes",
        "NoNewPrivileges=yes",
        "DevicePolicy=closed",
        "DeviceAllow=char-ttyUSB rw",
        "DeviceAllow=char-ttyACM rw",
        "RestrictAddressFamilies=AF_UNIX AF_INET AF_INET6 AF_CAN",
        "ReadWritePaths=/var/lib/motorbench/records",
        "--records /var/lib/motorbench/records",
        "--listen 127.0.0.1:",
    ] {
        assert!(UNIT.contains(line), "the unit lacks `{line}`");
    }
}

#[test]
fn unit_security_exposure_is_low() {
    let (_dir, unit) = unit_for_this_build();
    // Offline: no running systemd needed.
    let out = systemd_analyze(&["security", "--offline=true", "--no-pager"], &unit);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .find(|l| l.contains("Overall exposure level"))
        .unwrap_or_else(|| {
            panic!(
                "no exposure level:\n{stdout}\n{}",
                String::from_utf8_lossy(&out.stderr)
            )
        });
    let score: f64 = line
        .split(':')
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("cannot read the score in {line:?}"));
    println!("systemd-analyze security: {}", line.trim());
    // 0 is best, 10 worst; systemd calls ≤ 2 "OK".
    assert!(score <= 2.0, "{line}");
}
