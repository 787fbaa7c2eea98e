//! systemd integration: logging to journald when run as a service (plain
//! text on stderr otherwise), readiness and status notifications, and the
//! watchdog.
//!
//! The watchdog answers one question: is the daemon stuck? It is petted by
//! a task of its own on the runtime, so it stops when the runtime cannot
//! schedule it, and it stops on purpose when a running test's supervisor
//! has missed its own heartbeat or failed a safe-state command
//! ([`Daemon::healthy`]). Nothing else stops it: identification,
//! diagnosis and report writing run on blocking threads while the rig is
//! already safe, and a latched trip or a full connection table is a state
//! the API reports, not a reason for systemd to restart the daemon.

use std::sync::Arc;
use std::time::Duration;

use sd_notify::NotifyState;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::EnvFilter;

use super::state::Daemon;

/// Set up `tracing`: to journald when `JOURNAL_STREAM` says stderr is the
/// journal (run by systemd), else plain text on stderr. The level comes
/// from `RUST_LOG` (default `info`). Returns where logs go.
pub fn init_logging() -> &'static str {
    let filter = || EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    if std::env::var_os("JOURNAL_STREAM").is_some() {
        match tracing_journald::layer() {
            Ok(journald) => {
                let journald = journald.with_syslog_identifier("motorbench".into());
                if tracing_subscriber::registry()
                    .with(filter())
                    .with(journald)
                    .try_init()
                    .is_ok()
                {
                    return "journald";
                }
            }
            Err(e) => eprintln!("motorbench: journald unavailable ({e}); logging to stderr"),
        }
    }
    let _ = tracing_subscriber::registry()
        .with(filter())
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(std::io::stderr)
                .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
                .with_target(false),
        )
        .try_init();
    "stderr"
}

/// Tell systemd (when it started us with `Type=notify`) that the service
/// is ready, with a status line.
pub fn notify_ready(status: &str) {
    if let Err(e) = sd_notify::notify(&[NotifyState::Ready, NotifyState::Status(status)]) {
        tracing::warn!("sd_notify READY failed: {e}");
    }
}

/// Tell systemd the service is stopping.
pub fn notify_stopping() {
    let _ = sd_notify::notify(&[
        NotifyState::Stopping,
        NotifyState::Status("stopping: making the rigs safe and finishing records"),
    ]);
}

/// When systemd set `WatchdogSec=`, pet it at half the interval while
/// the daemon is not stuck ([`Daemon::healthy`], see the module docs);
/// when it is, stop petting, so systemd restarts the service (and each
/// power stage's own heartbeat has already made it safe).
pub fn spawn_watchdog(daemon: Arc<Daemon>) -> Option<tokio::task::JoinHandle<()>> {
    let interval = sd_notify::watchdog_enabled()?;
    let period = (interval / 2).max(Duration::from_millis(10));
    tracing::info!("systemd watchdog every {interval:?}; petting every {period:?} while healthy");
    Some(tokio::spawn(async move {
        let mut tick = tokio::time::interval(period);
        let mut was_healthy = true;
        loop {
            tick.tick().await;
            let healthy = daemon.healthy();
            if healthy {
                let _ = sd_notify::notify(&[NotifyState::Watchdog]);
                if !was_healthy {
                    tracing::info!(
                        "every running supervisor is healthy again: petting the watchdog"
                    );
                }
            } else if was_healthy {
                tracing::error!(
                    "a running test's safety supervisor is stuck or failed a safe-state \
                     command: no longer petting the watchdog"
                );
            }
            was_healthy = healthy;
        }
    }))
}
