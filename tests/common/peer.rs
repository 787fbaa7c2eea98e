//! Python peers (tests/python/*.py) as child processes: started with piped
//! standard input (closing it stops them), killed on drop.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

/// A running Python peer.
pub struct Peer {
    child: Child,
    stdin: Option<ChildStdin>,
    stdout: BufReader<ChildStdout>,
    name: String,
}

impl Peer {
    /// Start `tests/python/<script>` with `args`. The README's test command
    /// installs the Python packages; a missing one fails the test (the
    /// peer's error is in the panic message), it is never skipped.
    pub fn start(script: &str, args: &[&str]) -> Peer {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/python")
            .join(script);
        let mut child = Command::new(super::python::interpreter())
            .arg("-u")
            .arg(&path)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the test python runs");
        let stdin = child.stdin.take();
        let stdout = BufReader::new(child.stdout.take().expect("piped"));
        Peer {
            child,
            stdin,
            stdout,
            name: format!("{script} {}", args.join(" ")),
        }
    }

    /// The next line the peer prints; panics with its stderr if it ended.
    pub fn line(&mut self) -> String {
        let mut line = String::new();
        let n = self.stdout.read_line(&mut line).expect("read the peer");
        if n == 0 {
            let _ = self.child.kill();
            let out = self.child.wait_with_output_ref();
            panic!("peer `{}` ended without output:\n{out}", self.name);
        }
        line.trim_end().to_string()
    }

    /// Wait for the peer's `READY …` line; the text after `READY`.
    pub fn ready(&mut self) -> String {
        let line = self.line();
        line.strip_prefix("READY")
            .unwrap_or_else(|| panic!("peer `{}` said {line:?}, not READY", self.name))
            .trim()
            .to_string()
    }

    /// Send the peer one line on its standard input (a command).
    pub fn send(&mut self, line: &str) {
        use std::io::Write;
        let stdin = self.stdin.as_mut().expect("the peer's input is open");
        writeln!(stdin, "{line}").expect("write to the peer");
        stdin.flush().expect("flush to the peer");
    }

    /// Close the peer's standard input (it ends by itself).
    pub fn close_stdin(&mut self) {
        self.stdin.take();
    }

    /// Kill the peer at once (a pulled cable).
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

trait WaitRef {
    fn wait_with_output_ref(&mut self) -> String;
}

impl WaitRef for Child {
    fn wait_with_output_ref(&mut self) -> String {
        use std::io::Read;
        let _ = self.wait();
        let mut err = String::new();
        if let Some(e) = self.stderr.as_mut() {
            let _ = e.read_to_string(&mut err);
        }
        err
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        self.kill();
    }
}
