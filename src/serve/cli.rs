//! Command-line arguments of `motorbench serve` and `motorbench ctl`, and
//! their entry points (the binary's `main` only dispatches here).

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::{Args, Subcommand};

use super::client::{Client, Endpoint};
use super::ctl;
use super::{serve, Listen, ServeError, ServeOptions, DEFAULT_LISTEN};

/// `motorbench serve`.
#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Rig configuration (TOML); repeat for several rigs (each named after its file stem).
    #[arg(long, required = true)]
    pub config: Vec<PathBuf>,
    /// Records directory (MCAP, reports, plots, index.json).
    #[arg(long, default_value = "records")]
    pub records: PathBuf,
    /// TCP address of the API. Off the loopback interface, --token-file is required.
    #[arg(long, conflicts_with = "unix")]
    pub listen: Option<SocketAddr>,
    /// Listen on this Unix socket instead of TCP.
    #[arg(long)]
    pub unix: Option<PathBuf>,
    /// File holding the API token; every request must then send `Authorization: Bearer <token>`.
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// Most API connections open at once (lowered to fit the descriptor limit) [default: 256].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub max_connections: Option<u32>,
    /// Time a client has to send a request's headers (and body), also the idle timeout of a kept-alive connection.
    #[arg(long, default_value = "10s", value_parser = parse_timeout)]
    pub header_timeout: std::time::Duration,
}

/// A `--header-timeout` that cannot be used.
#[derive(Debug, thiserror::Error)]
enum TimeoutError {
    /// Not a duration.
    #[error(transparent)]
    Parse(#[from] humantime::DurationError),
    /// Out of range.
    #[error("must be between 10ms and 1h")]
    Range,
}

fn parse_timeout(text: &str) -> Result<std::time::Duration, TimeoutError> {
    let d = humantime::parse_duration(text)?;
    if d < std::time::Duration::from_millis(10) || d > std::time::Duration::from_secs(3600) {
        return Err(TimeoutError::Range);
    }
    Ok(d)
}

/// Run `serve` until SIGTERM or SIGINT; the exit code.
pub async fn run_serve(args: ServeArgs, stop: impl std::future::Future<Output = ()>) -> u8 {
    let logs = super::systemd::init_logging();
    let listen = match (args.unix, args.listen) {
        (Some(path), _) => Listen::Unix(path),
        (None, Some(addr)) => Listen::Tcp(addr),
        (None, None) => Listen::Tcp(DEFAULT_LISTEN.parse().expect("a valid default")),
    };
    tracing::info!(
        "motorbench {} serve; logs to {logs}",
        env!("CARGO_PKG_VERSION")
    );
    let opts = ServeOptions {
        configs: args.config,
        records: args.records,
        listen,
        token_file: args.token_file,
        max_connections: args.max_connections.map(|n| n as usize),
        header_timeout: args.header_timeout,
    };
    let announce = |address: &str| {
        use std::io::Write;
        // One line on stdout, for scripts and tests: where the API is.
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "listening on {address}");
        let _ = out.flush();
    };
    match serve(opts, stop, announce).await {
        Ok(()) => 0,
        Err(e) => {
            tracing::error!("{e}");
            eprintln!("motorbench: {e}");
            ServeError::exit_code(&e)
        }
    }
}

/// `motorbench ctl`.
#[derive(Debug, Args)]
pub struct CtlArgs {
    /// The daemon: http://HOST:PORT or unix:PATH [default: $MOTORBENCH_URL, else http://127.0.0.1:7461].
    #[arg(long)]
    pub url: Option<String>,
    /// File holding the API token [default: $MOTORBENCH_TOKEN_FILE, if set].
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// Print the daemon's JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// What to do.
    #[command(subcommand)]
    pub command: CtlCommand,
}

/// `motorbench ctl` subcommands.
#[derive(Debug, Subcommand)]
pub enum CtlCommand {
    /// Rigs and their state.
    Status,
    /// Start a test (the rig's configured plan, optionally overridden).
    Start {
        /// Rig name (default: the only rig).
        #[arg(long)]
        rig: Option<String>,
        /// Keys of [test] to override, as JSON, e.g. '{"levels_V": [60, 248], "coastdown": false}'.
        #[arg(long, conflicts_with = "test_file")]
        test_json: Option<String>,
        /// Keys of [test] to override, as a TOML file.
        #[arg(long)]
        test_file: Option<PathBuf>,
        /// Follow the test's progress until it ends.
        #[arg(long)]
        follow: bool,
    },
    /// Follow a test's progress until it ends (exit 0 completed, 3 aborted, 1 otherwise).
    Follow {
        /// Test id.
        id: String,
    },
    /// Abort a test: the rig goes to its safe state first.
    Abort {
        /// Test id (default: the test running on the only rig).
        id: Option<String>,
    },
    /// Emergency stop: stop the rig's test and latch the rig until `reset`.
    Estop {
        /// Rig name (default: the only rig).
        #[arg(long)]
        rig: Option<String>,
    },
    /// Clear a rig's latched stop.
    Reset {
        /// Rig name (default: the only rig).
        #[arg(long)]
        rig: Option<String>,
    },
    /// The records index, newest first.
    Records,
    /// Download a record's report and MCAP.
    Fetch {
        /// Record name.
        name: String,
        /// Directory to write into.
        #[arg(long, default_value = ".")]
        out: PathBuf,
    },
}

/// Run `ctl`; the exit code (messages already printed).
pub async fn run_ctl(args: CtlArgs) -> u8 {
    let url = args
        .url
        .or_else(|| std::env::var("MOTORBENCH_URL").ok())
        .unwrap_or_else(|| format!("http://{DEFAULT_LISTEN}"));
    let endpoint = match Endpoint::parse(&url) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("motorbench ctl: {e}");
            return 2;
        }
    };
    let token_file = args
        .token_file
        .or_else(|| std::env::var_os("MOTORBENCH_TOKEN_FILE").map(PathBuf::from));
    let token = match token_file {
        Some(p) => match std::fs::read_to_string(&p) {
            Ok(t) => Some(t.trim().to_string()),
            Err(e) => {
                eprintln!("motorbench ctl: {}: {e}", p.display());
                return 2;
            }
        },
        None => None,
    };
    let client = Client::new(endpoint, token);
    match ctl::run(&client, args.command, args.json).await {
        Ok(()) => 0,
        Err(f) => {
            eprintln!("motorbench ctl: {}", f.message);
            f.code
        }
    }
}
