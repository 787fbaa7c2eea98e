//! The daemon under test: `motorbench serve` started as a child process on
//! a configuration, its announced address, a client for its API, `ctl`
//! against it, and polling helpers. Shared by `tests/e2e/daemon.rs`,
//! `tests/e2e/daemon_modbus.rs` and `tests/daemon_im.rs`.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use motorbench::serve::client::{Client, Endpoint};
use serde_json::Value;

/// The binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_motorbench");

/// Longest any wait below may take before the test fails (a bound on
/// loops, not a timing requirement).
pub const PATIENCE: Duration = Duration::from_secs(180);

/// A running daemon; killed when dropped.
pub struct Served {
    /// The `serve` process.
    pub child: Child,
    /// The address it announced (`http://IP:PORT` or `unix:PATH`).
    pub url: String,
    log: PathBuf,
}

fn unique_suffix() -> u128 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos()
}

impl Served {
    /// Start `serve --config config --records records` with `extra`
    /// arguments, its log in `log_dir`; returns once it has announced its
    /// address.
    pub fn start(config: &Path, records: &Path, log_dir: &Path, extra: &[&str]) -> Served {
        Served::start_with_env(config, records, log_dir, extra, &[])
    }

    /// [`Served::start`] with environment variables set for the daemon.
    pub fn start_with_env(
        config: &Path,
        records: &Path,
        log_dir: &Path,
        extra: &[&str],
        env: &[(&str, &std::ffi::OsStr)],
    ) -> Served {
        let log = log_dir.join(format!(
            "serve-{}.log",
            std::process::id() as u128 + unique_suffix()
        ));
        let mut child = Command::new(BIN)
            .arg("serve")
            .arg("--config")
            .arg(config)
            .arg("--records")
            .arg(records)
            .args(extra)
            .envs(env.iter().copied())
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .expect("motorbench serve starts");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let url = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| {
                panic!(
                    "no address announced: {line:?}\n{}",
                    std::fs::read_to_string(&log).unwrap_or_default()
                )
            })
            .to_string();
        Served { child, url, log }
    }

    /// A client on the loopback address of the bound port.
    pub fn client(&self, token: Option<&str>) -> Client {
        let endpoint = match Endpoint::parse(&self.url).unwrap() {
            Endpoint::Tcp(a) => Endpoint::Tcp(a.replace("0.0.0.0", "127.0.0.1")),
            unix => unix,
        };
        Client::new(endpoint, token.map(str::to_string))
    }

    /// Run `motorbench ctl --url URL args…`.
    pub fn ctl(&self, args: &[&str]) -> Output {
        Command::new(BIN)
            .arg("ctl")
            .arg("--url")
            .arg(&self.url)
            .args(args)
            .output()
            .unwrap()
    }

    /// The daemon's log so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// GET `path`, which must succeed; its JSON.
pub async fn get(c: &Client, path: &str) -> Value {
    let r = c.get(path).await.unwrap();
    assert!(
        r.ok(),
        "GET {path}: {} {}",
        r.status,
        String::from_utf8_lossy(&r.body)
    );
    r.json()
}

/// Poll test `id` until `until` holds.
pub async fn wait_test(c: &Client, id: &str, until: impl Fn(&Value) -> bool) -> Value {
    let t0 = Instant::now();
    loop {
        let s = get(c, &format!("/v1/tests/{id}")).await;
        if until(&s) {
            return s;
        }
        assert!(t0.elapsed() < PATIENCE, "waited too long; last status {s}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// The test has finished.
pub fn finished(s: &Value) -> bool {
    s["state"] == "finished"
}

/// A shipped configuration file.
pub fn shipped(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(name)
}

/// A stand-in for systemd's notification socket (`NOTIFY_SOCKET`): a Unix
/// datagram socket bound by the test, with a thread noting when each
/// `WATCHDOG=1` arrives.
pub struct NotifySocket {
    /// The socket's path, for `NOTIFY_SOCKET`.
    pub path: PathBuf,
    pets: std::sync::Arc<std::sync::Mutex<Vec<Instant>>>,
    done: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl NotifySocket {
    /// Bind `dir/notify.sock` and start listening.
    pub fn bind(dir: &Path) -> NotifySocket {
        use std::sync::atomic::Ordering;
        let path = dir.join("notify.sock");
        let socket = std::os::unix::net::UnixDatagram::bind(&path).unwrap();
        // Wakes the thread now and then to see whether it should end.
        socket
            .set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        let pets = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (p, d) = (pets.clone(), done.clone());
        let thread = std::thread::spawn(move || {
            let mut buf = [0u8; 512];
            while !d.load(Ordering::Relaxed) {
                if let Ok(n) = socket.recv(&mut buf) {
                    if String::from_utf8_lossy(&buf[..n]).contains("WATCHDOG=1") {
                        p.lock().unwrap().push(Instant::now());
                    }
                }
            }
        });
        NotifySocket {
            path,
            pets,
            done,
            thread: Some(thread),
        }
    }

    /// `WATCHDOG=1` messages so far.
    pub fn pets(&self) -> usize {
        self.pets.lock().unwrap().len()
    }

    /// The largest time between two `WATCHDOG=1` messages so far.
    pub fn largest_gap(&self) -> Duration {
        let pets = self.pets.lock().unwrap();
        pets.windows(2)
            .map(|w| w[1] - w[0])
            .max()
            .unwrap_or_default()
    }

    /// The gaps between consecutive `WATCHDOG=1` messages so far.
    pub fn gaps(&self) -> Vec<Duration> {
        let pets = self.pets.lock().unwrap();
        pets.windows(2).map(|w| w[1] - w[0]).collect()
    }
}

impl Drop for NotifySocket {
    fn drop(&mut self) {
        self.done.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The token the web tests give their daemons.
pub const WEB_TOKEN: &str = "status-page-token-0123456789abcdef";

/// Start the daemon on the embedded default configuration, on loopback,
/// behind [`WEB_TOKEN`] (written to `dir/token`).
pub fn start_with_token(dir: &Path, records: &Path) -> Served {
    start_config_with_token(motorbench::config::DEFAULT_CONFIG, dir, records)
}

/// Start the daemon on the configuration `config` (its text, written to
/// `dir/rig.toml`: the rig is named `rig`), on loopback, behind
/// [`WEB_TOKEN`] (written to `dir/token`).
pub fn start_config_with_token(config: &str, dir: &Path, records: &Path) -> Served {
    let text = config;
    let config = dir.join("rig.toml");
    std::fs::write(&config, text).unwrap();
    let token_file = dir.join("token");
    std::fs::write(&token_file, format!("{WEB_TOKEN}\n")).unwrap();
    Served::start(
        &config,
        records,
        dir,
        &[
            "--listen",
            "127.0.0.1:0",
            "--token-file",
            token_file.to_str().unwrap(),
        ],
    )
}

/// Run `tests/python/SCRIPT` with `args` in the test Python; its output.
pub fn python_script(script: &str, args: &[&std::ffi::OsStr]) -> Output {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/python")
        .join(script);
    Command::new(super::python::interpreter())
        .arg(path)
        .args(args)
        .output()
        .expect("the test python runs")
}

/// The daemon's `/metrics` (`body`), parsed by the Prometheus client
/// library's OpenMetrics parser (`tests/python/parse_metrics.py`, strict:
/// a malformed exposition fails the test); the file goes in `dir`.
pub struct Metrics(pub Vec<Value>);

impl Metrics {
    /// Parse `body`.
    pub fn parse(body: &[u8], dir: &Path) -> Metrics {
        let file = dir.join("metrics.txt");
        std::fs::write(&file, body).unwrap();
        let out = python_script("parse_metrics.py", &[file.as_os_str()]);
        assert!(
            out.status.success(),
            "{}\n{}",
            String::from_utf8_lossy(&out.stderr),
            String::from_utf8_lossy(body)
        );
        Metrics(serde_json::from_slice(&out.stdout).unwrap())
    }

    /// GET `/metrics` from the daemon and parse it.
    pub async fn scrape(c: &Client, dir: &Path) -> Metrics {
        let r = c.get("/metrics").await.unwrap();
        assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
        Metrics::parse(&r.body, dir)
    }

    /// The sum of the samples named `motorbench_<name>` whose labels
    /// include `labels` (0 when none).
    pub fn value(&self, name: &str, labels: &[(&str, &str)]) -> f64 {
        self.matching(name, labels)
            .map(|s| s["value"].as_f64().unwrap())
            .sum()
    }

    /// How many samples are named `motorbench_<name>` with `labels`.
    pub fn count(&self, name: &str, labels: &[(&str, &str)]) -> usize {
        self.matching(name, labels).count()
    }

    fn matching<'a>(
        &'a self,
        name: &'a str,
        labels: &'a [(&'a str, &'a str)],
    ) -> impl Iterator<Item = &'a Value> + 'a {
        self.0.iter().filter(move |s| {
            s["name"] == format!("motorbench_{name}")
                && labels.iter().all(|(k, v)| s["labels"][*k] == *v)
        })
    }
}
