//! SLCAN frame rate of our codec and of python-can's `slcan` interface,
//! side by side in one run, on pseudo-terminal pairs (no hardware; a
//! pseudo-terminal does not pace bytes at a baud rate, so this measures
//! the software path of each implementation):
//!
//! - receive: the same text of `N` eight-byte standard frames is written
//!   into a pseudo-terminal as fast as it drains; the receiver (our
//!   [`SlcanStream`], or python-can's `can.Bus(interface="slcan")` in a
//!   child process, `benches/links_slcan_python.py`) decodes them; the
//!   rate is taken on the receiver's clock from its first frame to its
//!   `N`-th.
//! - send: the implementation sends `N` frames as fast as its `send`
//!   returns; a plain byte reader on the other end counts the lines; the
//!   rate is taken on the reader's clock from the first byte to the last
//!   frame's.
//!
//! `cargo bench --bench links_slcan_vs_python` prints both rates and their
//! ratios (best of `RUNS`). Needs python3 with python-can (the README's
//! test command installs it).

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use motorbench_drivers::can::{
    encode_frame, CanFrame, CanId, FrameStream, SlcanOptions, SlcanStream,
};
use motorbench_drivers::serial::port::{open_serial, pty_pair, SerialSettings};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// Frames per run.
const N: usize = 20_000;
/// Runs per measurement; the best is reported.
const RUNS: usize = 3;

fn frame() -> CanFrame {
    CanFrame::new(CanId::Standard(0x181), &[0, 1, 2, 3, 4, 5, 6, 7]).unwrap()
}

fn opts() -> SlcanOptions {
    SlcanOptions {
        bitrate: None,
        listen_only: false,
        ack_timeout: None,
    }
}

/// The text of `N` frames.
fn burst() -> Vec<u8> {
    let line = encode_frame(&frame());
    line.iter().copied().cycle().take(line.len() * N).collect()
}

/// Our receiver: frames per second over `N` frames.
async fn ours_recv() -> f64 {
    let pty = pty_pair().unwrap();
    let port = open_serial(&SerialSettings::new_8n1(&pty.device_path, 115_200)).unwrap();
    let mut rx = SlcanStream::open(port, "rx", opts()).await.unwrap();
    let mut host = pty.host;
    let writer = tokio::spawn(async move {
        AsyncWriteExt::write_all(&mut host, &burst()).await.unwrap();
        host
    });
    rx.recv().await.unwrap();
    let first = Instant::now();
    for _ in 1..N {
        rx.recv().await.unwrap();
    }
    let rate = (N - 1) as f64 / first.elapsed().as_secs_f64();
    drop(writer.await.unwrap());
    drop(pty.device_end);
    rate
}

/// Count `N` frame lines (`t…\r`) arriving on `io`, skipping setup
/// commands: frames per second from the first frame's first byte to the
/// last frame's end.
async fn drain<T: tokio::io::AsyncRead + Unpin>(io: &mut T) -> f64 {
    let mut buf = vec![0u8; 65536];
    let mut frames = 0usize;
    let mut first = None;
    // Whether the current line is a frame (None: at the start of a line).
    let mut in_frame: Option<bool> = None;
    while frames < N {
        let n = io.read(&mut buf).await.unwrap();
        assert!(n > 0, "the sender closed after {frames} frames");
        let now = Instant::now();
        for &b in &buf[..n] {
            match (in_frame, b) {
                (_, b'\r') => {
                    if in_frame == Some(true) {
                        frames += 1;
                    }
                    in_frame = None;
                }
                (None, b) => {
                    let frame = b == b't';
                    if frame {
                        first.get_or_insert(now);
                    }
                    in_frame = Some(frame);
                }
                _ => {}
            }
        }
    }
    (N - 1) as f64 / first.unwrap().elapsed().as_secs_f64()
}

/// Our sender.
async fn ours_send() -> f64 {
    let pty = pty_pair().unwrap();
    let port = open_serial(&SerialSettings::new_8n1(&pty.device_path, 115_200)).unwrap();
    let mut tx = SlcanStream::open(port, "tx", opts()).await.unwrap();
    let mut host = pty.host;
    let sender = tokio::spawn(async move {
        let f = frame();
        for _ in 0..N {
            tx.send(&f).await.unwrap();
        }
        tx
    });
    let rate = drain(&mut host).await;
    drop(sender.await.unwrap());
    drop(pty.device_end);
    rate
}

fn python(path: &str, mode: &str) -> std::process::Child {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/links_slcan_python.py");
    Command::new("python3")
        .arg(script)
        .args([path, mode, &N.to_string()])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs")
}

fn wait_for(child: &mut std::process::Child, word: &str) -> String {
    let out = child.stdout.as_mut().unwrap();
    let mut line = String::new();
    let mut reader = BufReader::new(out);
    loop {
        line.clear();
        let n = reader.read_line(&mut line).unwrap();
        assert!(n > 0, "python-can ended before {word}");
        if line.starts_with(word) {
            return line.trim().to_string();
        }
        assert!(!line.starts_with("TIMEOUT"), "python-can: {line}");
    }
}

/// python-can's receiver.
async fn python_recv() -> f64 {
    let pty = pty_pair().unwrap();
    let mut child = python(&pty.device_path, "recv");
    wait_for(&mut child, "READY");
    let mut host = pty.host;
    let writer = tokio::spawn(async move {
        AsyncWriteExt::write_all(&mut host, &burst()).await.unwrap();
        host
    });
    let line = tokio::task::spawn_blocking(move || {
        let l = wait_for(&mut child, "RATE");
        let _ = child.wait();
        l
    })
    .await
    .unwrap();
    drop(writer.await.unwrap());
    drop(pty.device_end);
    line[5..].parse().unwrap()
}

/// python-can's sender.
async fn python_send() -> f64 {
    let pty = pty_pair().unwrap();
    let mut child = python(&pty.device_path, "send");
    wait_for(&mut child, "READY");
    let mut host = pty.host;
    let rate = drain(&mut host).await;
    let mut child = tokio::task::spawn_blocking(move || {
        wait_for(&mut child, "SENT");
        child
    })
    .await
    .unwrap();
    drop(child.stdin.take());
    let _ = child.wait();
    drop(pty.device_end);
    rate
}

fn best(rates: &[f64]) -> f64 {
    rates.iter().copied().fold(0.0, f64::max)
}

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --benches` passes
    // nothing of the kind: then only check that it builds.
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    let rt = tokio::runtime::Runtime::new().unwrap();
    let mut r = [vec![], vec![], vec![], vec![]];
    for _ in 0..RUNS {
        r[0].push(rt.block_on(ours_recv()));
        r[1].push(rt.block_on(python_recv()));
        r[2].push(rt.block_on(ours_send()));
        r[3].push(rt.block_on(python_send()));
        std::thread::sleep(Duration::from_millis(100));
    }
    let [or, pr, os, ps] = [best(&r[0]), best(&r[1]), best(&r[2]), best(&r[3])];
    println!("SLCAN on a pseudo-terminal, {N} eight-byte standard frames, best of {RUNS}:");
    println!(
        "  receive: ours {or:.0} frames/s, python-can {pr:.0} frames/s, ratio {:.1}",
        or / pr
    );
    println!(
        "  send:    ours {os:.0} frames/s, python-can {ps:.0} frames/s, ratio {:.1}",
        os / ps
    );
    println!("  all runs (frames/s): ours recv {:?}, python-can recv {:?}, ours send {:?}, python-can send {:?}",
        r[0].iter().map(|x| x.round()).collect::<Vec<_>>(),
        r[1].iter().map(|x| x.round()).collect::<Vec<_>>(),
        r[2].iter().map(|x| x.round()).collect::<Vec<_>>(),
        r[3].iter().map(|x| x.round()).collect::<Vec<_>>());
}
