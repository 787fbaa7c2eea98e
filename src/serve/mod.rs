//! The daemon (`motorbench serve`): a control API over HTTP/JSON on the
//! loopback interface or a Unix socket, one test at a time per rig, the
//! safety supervisor around every test, records in a directory with an
//! index, systemd notification and watchdog; and the `motorbench ctl`
//! client.
//!
//! - [`serve`]: bind, announce, serve until the shutdown future resolves,
//!   then stop running tests safely and finish their records.
//! - [`api`]: the HTTP endpoints and their OpenAPI document. [`auth`]:
//!   the bearer token. [`metrics`]: `/metrics` (a running test's bus
//!   counts through [`link_tally`]). [`page`]: the status page at `/`.
//! - [`state`]: rigs, tests, the index. [`rig_config`]: a DC or an
//!   induction-machine rig. [`jobs`]: one test of any machine, over the
//!   one session ([`crate::session`]).
//! - [`records_index`]: the index file, interrupted records, retention.
//! - [`client`] and [`ctl`]: the command-line client.

pub mod api;
pub mod auth;
pub mod cli;
pub mod client;
pub mod connections;
pub mod ctl;
pub mod heap;
pub mod jobs;
pub mod latch_file;
pub mod link_tally;
pub mod metrics;
pub mod page;
pub mod records_index;
pub mod rig_config;
pub mod state;
pub mod systemd;

use std::future::Future;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use thiserror::Error;

use crate::config::ConfigError;
use auth::{Token, TokenError};
use rig_config::RigConfig;
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
    /// Most API connections open at once (lowered below the descriptor
    /// limit; default [`connections::DEFAULT_MAX_CONNECTIONS`]).
    pub max_connections: Option<usize>,
    /// Header, idle and body timeout of an API connection.
    pub header_timeout: Duration,
}

/// Why the daemon could not start or stopped with an error.
#[derive(Debug, Error)]
pub enum ServeError {
    /// A configuration is not usable.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The options are refused (e.g. no token off loopback).
    #[error("{0}")]
    Refused(String),
    /// The token file is refused.
    #[error(transparent)]
    Token(#[from] TokenError),
    /// Binding, the records directory or the server failed.
    #[error("{0}")]
    Io(String),
}

impl ServeError {
    /// Exit code: 2 for bad input, 1 for runtime failures.
    pub fn exit_code(&self) -> u8 {
        match self {
            ServeError::Config(_) | ServeError::Refused(_) | ServeError::Token(_) => 2,
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
        let cfg = RigConfig::load(path)?;
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
        Some(p) => Some(Token::load(p)?),
        None => None,
    };
    check_listen_policy(&opts.listen, token.as_ref())?;
    let nofile = connections::descriptor_limit();
    let limits =
        connections::ConnectionLimits::new(opts.max_connections, opts.header_timeout, nofile);
    let (listener, address) = match &opts.listen {
        Listen::Tcp(addr) => {
            let listener = tokio::net::TcpListener::bind(addr)
                .await
                .map_err(|e| ServeError::Io(format!("cannot listen on {addr}: {e}")))?;
            let bound = listener
                .local_addr()
                .map_err(|e| ServeError::Io(e.to_string()))?;
            (
                connections::Listener::Tcp(listener),
                format!("http://{bound}"),
            )
        }
        Listen::Unix(path) => (
            connections::Listener::Unix(bind_unix(path)?),
            format!("unix:{}", path.display()),
        ),
    };
    // Opened after binding: a daemon refused its address leaves the records alone.
    let daemon =
        Arc::new(Daemon::new(rigs, &opts.records).map_err(|e| ServeError::Io(e.to_string()))?);
    let apps = connections::Apps {
        full: api::router(daemon.clone(), token.clone()),
        stops: api::stop_router(daemon.clone(), token.clone()),
    };
    let (stop_http, stop_http_rx) = tokio::sync::watch::channel(false);
    let mut server = tokio::spawn(connections::serve_connections(
        listener,
        apps,
        limits,
        stop_http_rx,
        // Live feeds end with their tests; give open connections a moment.
        Duration::from_secs(3),
    ));
    let auth = if token.is_some() {
        "token required"
    } else {
        "no token"
    };
    tracing::info!(
        "listening on {address} ({auth}); rigs: {}; records in {}; at most {} API connections \
         (descriptor limit {}), header and idle timeout {:?}",
        daemon.rig_names().join(", "),
        opts.records.display(),
        limits.max,
        nofile.map_or_else(|| "none".to_string(), |n| n.to_string()),
        limits.header_timeout,
    );
    let estop_signal = estop_signal(daemon.clone())?;
    announce(&address);
    systemd::notify_ready(&format!("listening on {address}"));
    let watchdog = systemd::spawn_watchdog(daemon.clone());

    tokio::select! {
        _ = shutdown => tracing::info!("stop requested: making the rigs safe and finishing records"),
        r = &mut server => {
            let why = match r {
                Ok(()) => "it ended".to_string(),
                Err(e) => e.to_string(),
            };
            return Err(ServeError::Io(format!("the API server stopped: {why}")));
        }
    }
    systemd::notify_stopping();
    daemon.shutdown().await;
    estop_signal.abort();
    if let Some(w) = watchdog {
        w.abort();
    }
    let _ = stop_http.send(true);
    let _ = server.await;
    if let Listen::Unix(path) = &opts.listen {
        let _ = std::fs::remove_file(path);
    }
    tracing::info!("stopped");
    Ok(())
}

/// `SIGUSR1`: an emergency stop on every rig (safe state first, then the
/// latch), the path that needs no API connection. The handler is
/// installed before the daemon announces itself.
fn estop_signal(daemon: Arc<Daemon>) -> Result<tokio::task::JoinHandle<()>, ServeError> {
    use tokio::signal::unix::{signal, SignalKind};
    let mut usr1 = signal(SignalKind::user_defined1())
        .map_err(|e| ServeError::Io(format!("cannot handle SIGUSR1: {e}")))?;
    Ok(tokio::spawn(async move {
        while usr1.recv().await.is_some() {
            for rig in daemon.rig_names() {
                if let Err(e) = daemon.emergency_stop(&rig, "SIGUSR1").await {
                    tracing::error!("SIGUSR1: emergency stop on rig {rig}: {e:?}");
                }
            }
        }
    }))
}

/// Bind the API's Unix socket at `path`. A socket already there that
/// answers belongs to a live daemon: refused. One nobody answers on was
/// left by a daemon that did not stop cleanly: replaced. The socket is
/// bound in a private directory (mode 0700) beside `path`, given mode 0660
/// and then linked into place, so it is never reachable with a wider mode
/// whatever the umask.
fn bind_unix(path: &Path) -> Result<tokio::net::UnixListener, ServeError> {
    use std::os::unix::fs::{DirBuilderExt, FileTypeExt, PermissionsExt};
    let shown = path.display();
    if let Ok(m) = std::fs::symlink_metadata(path) {
        if !m.file_type().is_socket() {
            return Err(ServeError::Refused(format!(
                "{shown}: exists and is not a socket"
            )));
        }
        match std::os::unix::net::UnixStream::connect(path) {
            Ok(_) => {
                return Err(ServeError::Refused(format!(
                    "{shown}: another daemon is listening on this socket; stop it first"
                )))
            }
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {
                tracing::info!("{shown}: removing a stale socket nobody listens on");
                std::fs::remove_file(path).map_err(|e| ServeError::Io(format!("{shown}: {e}")))?;
            }
            Err(e) => {
                return Err(ServeError::Refused(format!(
                    "{shown}: a socket is there and cannot be checked ({e}); remove it if no \
                     daemon uses it"
                )))
            }
        }
    }
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let private = parent.join(format!(".{}", std::process::id()));
    std::fs::DirBuilder::new()
        .mode(0o700)
        .create(&private)
        .map_err(|e| ServeError::Io(format!("{}: {e}", private.display())))?;
    let staged = private.join("s");
    let bound = (|| {
        let listener = tokio::net::UnixListener::bind(&staged)
            .map_err(|e| format!("cannot listen on {shown}: {e}"))?;
        // Owner and group only: the socket's permissions are its access control.
        std::fs::set_permissions(&staged, std::fs::Permissions::from_mode(0o660))
            .map_err(|e| format!("{}: {e}", staged.display()))?;
        // A link fails if the path exists: a daemon that bound it meanwhile keeps it.
        std::fs::hard_link(&staged, path).map_err(|e| format!("cannot listen on {shown}: {e}"))?;
        Ok(listener)
    })();
    let _ = std::fs::remove_file(&staged);
    let _ = std::fs::remove_dir(&private);
    bound.map_err(ServeError::Io)
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
