//! The daemon (`motorbench serve`): a control API over HTTP/JSON on the
//! loopback interface or a Unix socket, one test at a time per rig, the
//! safety supervisor around every test, records in a directory with an
//! index, systemd notification and watchdog; and the `motorbench ctl`
//! client.
//!
//! - [`serve`]: bind, announce, serve until the shutdown future resolves,
//!   then stop running tests safely and finish their records.
//! - [`api`]: the HTTP endpoints. [`auth`]: the bearer token.
//! - [`state`]: rigs, tests, the index. [`rig_config`]: a DC or an
//!   induction-machine rig. [`jobs`]: one test, and what every test
//!   shares; [`im_jobs`]: an induction-machine slip sweep.
//! - [`records_index`]: the index file, interrupted records, retention.
//! - [`client`] and [`ctl`]: the command-line client.

pub mod api;
pub mod auth;
pub mod cli;
pub mod client;
pub mod ctl;
pub mod im_jobs;
pub mod jobs;
pub mod records_index;
pub mod rig_config;
pub mod state;
pub mod systemd;
pub mod test_override;

use std::future::Future;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use thiserror::Error;

use crate::config::ConfigError;
use auth::Token;
use rig_config::{RigConfig, RigConfigError};
use state::Daemon;

/// Default address of the control API.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:7461";

/// Where the API listens.
#[derive(Debug, Clone, PartialEq)]
pub enum Listen {
    /// A TCP address.
    Tcp(SocketAddr),
    /// A Unix socket path.
    Unix(PathBuf),
}

/// What `motorbench serve` was asked.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// One configuration per rig; the rig is named after the file stem.
    pub configs: Vec<PathBuf>,
    /// Records directory.
    pub records: PathBuf,
    /// Where to listen.
    pub listen: Listen,
    /// File holding the API token.
    pub token_file: Option<PathBuf>,
}

/// Why the daemon could not start or stopped with an error.
#[derive(Debug, Error)]
pub enum ServeError {
    /// A configuration is not usable.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An induction-machine configuration is not usable.
    #[error("{0}")]
    ImConfig(String),
    /// The options are refused (e.g. no token off loopback).
    #[error("{0}")]
    Refused(String),
    /// Binding, the records directory or the server failed.
    #[error("{0}")]
    Io(String),
}

impl ServeError {
    /// Exit code: 2 for bad input, 1 for runtime failures.
    pub fn exit_code(&self) -> u8 {
        match self {
            ServeError::Config(_) | ServeError::ImConfig(_) | ServeError::Refused(_) => 2,
            ServeError::Io(_) => 1,
        }
    }
}

/// The rigs of `configs`: (name, configuration), names from file stems.
pub fn load_rigs(configs: &[PathBuf]) -> Result<Vec<(String, RigConfig)>, ServeError> {
    if configs.is_empty() {
        return Err(ServeError::Refused(
            "serve needs at least one --config (one per rig)".into(),
        ));
    }
    let mut rigs: Vec<(String, RigConfig)> = Vec::new();
    for path in configs {
        let cfg = RigConfig::load(path).map_err(|e| match e {
            RigConfigError::Dc(e) => ServeError::Config(e),
            RigConfigError::Im(e) => ServeError::ImConfig(e),
        })?;
        let name = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("rig")
            .to_string();
        if rigs.iter().any(|(n, _)| *n == name) {
            return Err(ServeError::Refused(format!(
                "{}: two configurations would both be rig `{name}` (rigs are named after the file stem)",
                path.display()
            )));
        }
        rigs.push((name, cfg));
    }
    Ok(rigs)
}

/// The token policy: off loopback a token is required.
pub fn check_listen_policy(listen: &Listen, token: Option<&Token>) -> Result<(), ServeError> {
    if let Listen::Tcp(addr) = listen {
        if !addr.ip().is_loopback() && token.is_none() {
            return Err(ServeError::Refused(format!(
                "refusing to listen on {addr} without --token-file: off the loopback \
                 interface every request must carry a token"
            )));
        }
    }
    Ok(())
}

/// Run the daemon until `shutdown` resolves; then stop running tests
/// (safe state first), finish their records and return. `announce` is
/// called once with the bound address (`http://IP:PORT` or
/// `unix:PATH`), after which the API answers.
pub async fn serve(
    opts: ServeOptions,
    shutdown: impl Future<Output = ()>,
    announce: impl FnOnce(&str),
) -> Result<(), ServeError> {
    let rigs = load_rigs(&opts.configs)?;
    let token = match &opts.token_file {
        Some(p) => Some(Token::load(p).map_err(ServeError::Refused)?),
        None => None,
    };
    check_listen_policy(&opts.listen, token.as_ref())?;
    let daemon =
        Arc::new(Daemon::new(rigs, &opts.records).map_err(|e| ServeError::Io(e.to_string()))?);
    let app = api::router(daemon.clone(), token.clone());
    let (stop_http, stop_http_rx) = tokio::sync::oneshot::channel::<()>();
    let graceful = async move {
        let _ = stop_http_rx.await;
    };
    let (address, mut server) = match &opts.listen {
        Listen::Tcp(addr) => {
            let listener = tokio::net::TcpListener::bind(addr)
                .await
                .map_err(|e| ServeError::Io(format!("cannot listen on {addr}: {e}")))?;
            let bound = listener
                .local_addr()
                .map_err(|e| ServeError::Io(e.to_string()))?;
            let server = tokio::spawn(async move {
                axum::serve(listener, app)
                    .with_graceful_shutdown(graceful)
                    .await
            });
            (format!("http://{bound}"), server)
        }
        Listen::Unix(path) => {
            let listener = bind_unix(path)?;
            let server = tokio::spawn(async move {
                axum::serve(listener, app)
                    .with_graceful_shutdown(graceful)
                    .await
            });
            (format!("unix:{}", path.display()), server)
        }
    };
    let auth = if token.is_some() {
        "token required"
    } else {
        "no token"
    };
    tracing::info!(
        "listening on {address} ({auth}); rigs: {}; records in {}",
        daemon.rig_names().join(", "),
        opts.records.display()
    );
    announce(&address);
    systemd::notify_ready(&format!("listening on {address}"));
    let watchdog = systemd::spawn_watchdog(daemon.clone());

    tokio::select! {
        _ = shutdown => tracing::info!("stop requested: making the rigs safe and finishing records"),
        r = &mut server => {
            let why = match r {
                Ok(Ok(())) => "it ended".to_string(),
                Ok(Err(e)) => e.to_string(),
                Err(e) => e.to_string(),
            };
            return Err(ServeError::Io(format!("the API server stopped: {why}")));
        }
    }
    systemd::notify_stopping();
    daemon.shutdown().await;
    if let Some(w) = watchdog {
        w.abort();
    }
    let _ = stop_http.send(());
    // Live feeds end with their tests; give open connections a moment.
    if tokio::time::timeout(Duration::from_secs(3), server)
        .await
        .is_err()
    {
        tracing::warn!("closing API connections that were still open");
    }
    if let Listen::Unix(path) = &opts.listen {
        let _ = std::fs::remove_file(path);
    }
    tracing::info!("stopped");
    Ok(())
}

fn bind_unix(path: &Path) -> Result<tokio::net::UnixListener, ServeError> {
    use std::os::unix::fs::{FileTypeExt, PermissionsExt};
    if let Ok(m) = std::fs::symlink_metadata(path) {
        if m.file_type().is_socket() {
            // A socket left by a daemon that did not stop cleanly.
            let _ = std::fs::remove_file(path);
        } else {
            return Err(ServeError::Refused(format!(
                "{}: exists and is not a socket",
                path.display()
            )));
        }
    }
    let listener = tokio::net::UnixListener::bind(path)
        .map_err(|e| ServeError::Io(format!("cannot listen on {}: {e}", path.display())))?;
    // Owner and group only: the socket's permissions are its access control.
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o660))
        .map_err(|e| ServeError::Io(format!("{}: {e}", path.display())))?;
    Ok(listener)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn off_loopback_needs_a_token() {
        let lo: SocketAddr = "127.0.0.1:0".parse().unwrap();
        let lo6: SocketAddr = "[::1]:0".parse().unwrap();
        let any: SocketAddr = "0.0.0.0:0".parse().unwrap();
        assert!(check_listen_policy(&Listen::Tcp(lo), None).is_ok());
        assert!(check_listen_policy(&Listen::Tcp(lo6), None).is_ok());
        assert!(check_listen_policy(&Listen::Unix("/tmp/x.sock".into()), None).is_ok());
        let e = check_listen_policy(&Listen::Tcp(any), None).unwrap_err();
        assert!(e.to_string().contains("--token-file"), "{e}");
        assert_eq!(e.exit_code(), 2);
        let t = Token::from_text("0123456789abcdef");
        assert!(check_listen_policy(&Listen::Tcp(any), Some(&t)).is_ok());
    }
}
