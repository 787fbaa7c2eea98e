//! Sustained rates of the links, on this machine (loopback and
//! pseudo-terminals, no hardware), and the serial links held against
//! their line limits on a line paced at the baud rate:
//!
//! - `modbus_tcp/*`: one poll of the DAQ's three channels (6 input
//!   registers, one request) against the tokio-modbus server on 127.0.0.1,
//!   through the client alone and through the bus task (the bench's path).
//! - `modbus_rtu_pty/*`: the same poll over Modbus RTU on a pseudo-terminal
//!   pair opened at 115200 baud. A pseudo-terminal does not pace bytes at
//!   the baud rate: this measures the software path; the line's own limit
//!   is printed beside it (computed, not measured).
//! - `slcan_pty/1000_frames`: 1000 eight-byte frames from one SLCAN stream
//!   to another over a pseudo-terminal pair.
//! - `bus_limits` (plain timed loops after the criterion groups, each run
//!   [`REPEATS`] times): the bus limits. The same RTU poll and the
//!   same SLCAN frames go through a [`PacedLine`], a relay between two
//!   pseudo-terminals that carries bytes no faster than a UART at the baud
//!   rate, and their rates are held against the line's limits, at 8N1
//!   (10 bits per byte, 86.8 µs per byte at 115200 baud):
//!   - Modbus RTU, a read of N registers in one request: 8 bytes out
//!     (address, function, start, count, CRC) and 5 + 2N back (address,
//!     function, byte count, data, CRC), so polls/s = 1 / ((13 + 2N) × 10
//!     / baud + 2 × t_silence). For the DAQ's N = 6 at 115200 baud: 25
//!     bytes, 2.170 ms; with the spec's fixed 1.75 ms of silence before
//!     each frame above 19200 baud (what the client keeps before its
//!     requests, `rtu_frame_gap`) 176 polls/s (the ratio `modbus_rtu`),
//!     with 3.5 characters (0.304 ms) 360 polls/s, with none 461 polls/s
//!     (the line's ceiling).
//!   - SLCAN, an 8-byte standard frame is `t` + 3 id + 1 length + 16 data
//!     hex digits + `\r` = 22 characters: frames/s = baud / (10 × 22),
//!     523.6 at 115200 baud. `SlcanStream::send` waits for no answer;
//!     `ack_timeout` only governs the setup commands of `open`, and is
//!     `None` here because the peer is another host, which never answers.
//!
//!   Before them the relay itself is measured: its byte rate from a sender
//!   that writes as fast as it can (it should be baud / 10), the error of
//!   every delivery against the line clock, and a bare exchange of the RTU
//!   poll's sizes (8 bytes out, 17 back, an echo at the far end) through
//!   the line and, back to back, over one pseudo-terminal pair without it,
//!   to show what the line, the relay and the pseudo-terminals leave for
//!   Modbus itself. Each result ends in a line `ratio <name>
//!   <measured/limit> limit=<x>/s measured=<y>/s`, the median of the runs.
//!
//! `cargo bench --bench links` runs everything; `cargo bench --bench links
//! -- bus_limits` only the paced loops (about 70 s). Criterion's rates
//! are 1 / (time per iteration), ×1000 for the frame burst.

use std::fs::File;
use std::io;
use std::os::fd::{AsRawFd, BorrowedFd};
use std::path::Path;
use std::sync::mpsc::{Receiver, SyncSender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use motorbench_drivers::can::{
    encode_frame, CanFrame, CanId, FrameStream, SlcanOptions, SlcanStream,
};
use motorbench_drivers::modbus::server::{
    serve_rtu, serve_tcp, BankService, PassiveDevice, RegisterBank,
};
use motorbench_drivers::modbus::{
    read_registers, rtu_frame_gap, spawn_bus, CallPolicy, DeviceProfile, ModbusClient, Priority,
    Register,
};
use motorbench_drivers::serial::port::{open_serial, pty_pair, SerialSettings, SerialStream};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::runtime::Runtime;

fn daq() -> (DeviceProfile, Vec<Register>) {
    let p = DeviceProfile::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("config/devices/sim-daq.toml"),
    )
    .unwrap();
    let regs = ["armature_voltage", "armature_current", "encoder_count"]
        .iter()
        .map(|n| p.register(n).unwrap().clone())
        .collect();
    (p, regs)
}

fn service(p: &DeviceProfile) -> BankService {
    let bank = Arc::new(Mutex::new(RegisterBank::for_profile(p)));
    BankService::new(1, bank, Arc::new(PassiveDevice))
}

fn policy() -> CallPolicy {
    CallPolicy {
        timeout: Duration::from_secs(1),
        retries: 0,
        retry_delay: Duration::ZERO,
    }
}

/// Theoretical Modbus RTU polls per second for a read of `registers`
/// registers at `baud` with `bits` bits per byte and `gap_s` of silence
/// before each frame (request and answer), device turnaround not counted.
fn rtu_limit(registers: u32, baud: f64, bits: f64, gap_s: f64) -> f64 {
    let bytes = 8.0 + 5.0 + 2.0 * f64::from(registers);
    1.0 / (bytes * bits / baud + 2.0 * gap_s)
}

fn modbus(c: &mut Criterion) {
    let rt = Runtime::new().unwrap();
    let (p, regs) = daq();

    // TCP on loopback.
    let (addr, _server) = rt.block_on(async {
        let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        serve_tcp(l, service(&p)).unwrap()
    });
    let client = tokio::sync::Mutex::new(ModbusClient::tcp("bench", addr, 1, policy()));
    let mut g = c.benchmark_group("modbus_tcp");
    g.bench_function("client_poll_3_channels", |b| {
        b.to_async(&rt).iter(|| async {
            let mut client = client.lock().await;
            read_registers(&mut client, &regs, 0).await.unwrap()
        })
    });
    let bus = rt.block_on(async { spawn_bus(ModbusClient::tcp("bench", addr, 1, policy())) });
    g.bench_function("bus_task_poll_3_channels", |b| {
        b.to_async(&rt)
            .iter(|| async { bus.read(1, regs.clone(), Priority::Routine).await.unwrap() })
    });
    g.finish();

    // RTU on a pseudo-terminal, opened by path at 115200 baud.
    let (path, _pty_end) = rt.block_on(async {
        let pty = pty_pair().unwrap();
        let path = pty.device_path.clone();
        serve_rtu(pty.host, service(&p));
        (path, pty.device_end)
    });
    let bus = rt.block_on(async {
        spawn_bus(ModbusClient::rtu(
            "bench",
            SerialSettings::new_8n1(&path, 115_200),
            1,
            policy(),
        ))
    });
    let mut g = c.benchmark_group("modbus_rtu_pty");
    g.bench_function("bus_task_poll_3_channels", |b| {
        b.to_async(&rt)
            .iter(|| async { bus.read(1, regs.clone(), Priority::Routine).await.unwrap() })
    });
    g.finish();
    eprintln!(
        "modbus RTU at 115200 baud 8N1, 6-register read: line limit {:.0} polls/s with 3.5-character gaps, \
         {:.0} polls/s with the spec's fixed 1.75 ms gap above 19200 baud (device turnaround not counted)",
        rtu_limit(6, 115_200.0, 10.0, 3.5 * 10.0 / 115_200.0),
        rtu_limit(6, 115_200.0, 10.0, 1.75e-3)
    );
}

fn slcan(c: &mut Criterion) {
    let rt = Runtime::new().unwrap();
    let opts = SlcanOptions {
        ack_timeout: None,
        ..SlcanOptions::default()
    };
    let (tx, rx, _end) = rt.block_on(async {
        let pty = pty_pair().unwrap();
        let other = open_serial(&SerialSettings::new_8n1(&pty.device_path, 115_200)).unwrap();
        let tx = SlcanStream::open(pty.host, "tx", opts).await.unwrap();
        let rx = SlcanStream::open(other, "rx", opts).await.unwrap();
        (
            tokio::sync::Mutex::new(tx),
            tokio::sync::Mutex::new(rx),
            pty.device_end,
        )
    });
    // The receiving end sees the sender's setup commands first; they are
    // not frames and are skipped.
    let frame = can_frame();
    let mut g = c.benchmark_group("slcan_pty");
    g.bench_function("1000_frames", |b| {
        b.to_async(&rt).iter(|| async {
            let (mut tx, mut rx) = (tx.lock().await, rx.lock().await);
            let send = async {
                for _ in 0..1000 {
                    tx.send(&frame).await.unwrap();
                }
            };
            let recv = async {
                for _ in 0..1000 {
                    rx.recv().await.unwrap();
                }
            };
            tokio::join!(send, recv);
        })
    });
    g.finish();
    // An 8-byte standard frame is 22 characters of SLCAN text.
    eprintln!(
        "SLCAN line limit for 8-byte standard frames at 115200 baud 8N1 (UART adapters): {:.0} frames/s; \
         CAN at 500 kbit/s carries at most about {:.0} such frames/s (111 bits + stuffing + 3 bits interframe, ~125 bits)",
        115_200.0 / (22.0 * 10.0),
        500_000.0 / 125.0
    );
}

// The paced line and the bus-limit measurements.

/// Baud rate of the paced SLCAN link and of the relay's calibration (the
/// DAQ profile's RTU line has its own, also 115200).
const BAUD: u32 = 115_200;
/// Bits per byte at 8N1: start, 8 data, stop.
const BITS_8N1: u32 = 10;
/// Runs of each paced measurement; the median is reported.
const REPEATS: usize = 3;
/// Most line time one delivery of a [`PacedLine`] carries: a burst is
/// delivered piece by piece, as a receiver on a real line gets it.
const SLICE_S: f64 = 2e-3;
/// Chunks a [`PacedLine`] holds per direction beyond the pseudo-terminal's
/// own buffer, like a UART's transmit buffer: a sender further ahead waits.
const QUEUED_CHUNKS: usize = 8;
/// Ceiling of a [`PacedLine`]'s estimate of its own wake-up and write delay.
const MAX_LEAD: Duration = Duration::from_micros(300);

/// What one direction of a [`PacedLine`] carried since its log was last
/// taken.
#[derive(Debug, Default)]
struct LineLog {
    /// Bytes carried.
    bytes: u64,
    /// For each delivery: when its bytes were in the far end minus when
    /// the line would have carried their last byte, in nanoseconds
    /// (negative: early).
    error_ns: Vec<i64>,
}

/// A serial line between two pseudo-terminals that carries bytes no faster
/// than a UART at `baud`: a pseudo-terminal alone moves bytes as fast as
/// they are written, whatever baud rate it is opened at.
///
/// The relay holds one end of each pseudo-terminal (the parties use the
/// other ends) and moves bytes with two threads per direction, on blocking
/// file descriptors:
///
/// - a reader that reads whatever has arrived (at most [`SLICE_S`] of
///   line time at once) and stamps it with the time it arrived;
/// - a pacer that keeps a virtual line clock, "the line is free at". A
///   chunk starts when the line is free or when it arrived, whichever is
///   later, so chunks queued while the line is busy follow back to back
///   and idle time banks no credit; a chunk of n bytes keeps the line busy
///   n × bits per byte / baud seconds. The pacer writes the chunk to the
///   far end when the line would have carried its last byte.
///
/// Delivering at a chunk's last byte, not its first, hands the receiver a
/// frame when a receiver on a real line would have it whole: a request and
/// its answer then cost the line time of both frames plus what the
/// software at either end adds, as on a real line. (Writing a chunk at
/// once and only holding back the next would let an exchange run faster
/// than the line.) The arrival stamp comes from a thread that does nothing
/// but read, so it is late only by that thread's wake-up, where a UART
/// driver's write would also take a moment to reach the wire.
///
/// The pacer sleeps with `std::thread::sleep`, not tokio's timer, whose
/// 1 ms granularity would add up to a millisecond to every delivery. It
/// aims early by a running estimate of its own wake-up and write delay, so
/// deliveries are on time on average without busy-waiting; every
/// delivery's error is logged ([`LineLog`]). A direction's threads end
/// when the party's end they read from is closed or a write fails.
struct PacedLine {
    /// Logs of the direction `a` → `b` and of `b` → `a`.
    logs: [Arc<Mutex<LineLog>>; 2],
}

impl PacedLine {
    /// Join `a` and `b` (the relay's ends of two pseudo-terminals) by a
    /// line at `baud` with `bits` bits per byte. The relay takes their
    /// file descriptors over, blocking, off the runtime.
    fn start(a: SerialStream, b: SerialStream, baud: u32, bits: u32) -> PacedLine {
        let byte_s = f64::from(bits) / f64::from(baud);
        let (a, b) = (blocking(a), blocking(b));
        let logs: [Arc<Mutex<LineLog>>; 2] = Default::default();
        for (name, from, to, log) in [
            (
                "a-to-b",
                a.try_clone().unwrap(),
                b.try_clone().unwrap(),
                &logs[0],
            ),
            ("b-to-a", b, a, &logs[1]),
        ] {
            let (tx, rx) = std::sync::mpsc::sync_channel(QUEUED_CHUNKS);
            let chunk = ((SLICE_S / byte_s) as usize).max(1);
            std::thread::Builder::new()
                .name(format!("line-read-{name}"))
                .spawn(move || read_arrivals(from, chunk, tx))
                .unwrap();
            let log = Arc::clone(log);
            std::thread::Builder::new()
                .name(format!("line-pace-{name}"))
                .spawn(move || pace(rx, to, byte_s, log))
                .unwrap();
        }
        PacedLine { logs }
    }

    /// Both directions' logs (`a` → `b`, `b` → `a`), emptied.
    fn take(&self) -> [LineLog; 2] {
        self.logs
            .each_ref()
            .map(|l| std::mem::take(&mut *l.lock().unwrap()))
    }
}

/// `s`'s file descriptor as a blocking file, `s` itself closed (and so
/// deregistered from its runtime).
fn blocking(s: SerialStream) -> File {
    // SAFETY: the descriptor is `s`'s, open while `s` is; it is duplicated
    // before `s` is dropped.
    let fd = unsafe { BorrowedFd::borrow_raw(s.as_raw_fd()) }
        .try_clone_to_owned()
        .unwrap();
    drop(s);
    // The duplicate shares the open file and its flags: now that the
    // runtime has let go of it, clear its O_NONBLOCK.
    rustix::io::ioctl_fionbio(&fd, false).unwrap();
    File::from(fd)
}

/// A [`PacedLine`]'s reader: chunks of at most `chunk` bytes from `from`,
/// each stamped with when it was read, until `from` or the pacer closes.
fn read_arrivals(mut from: File, chunk: usize, to_pacer: SyncSender<(Instant, Vec<u8>)>) {
    let mut buf = vec![0u8; chunk];
    while let Ok(n @ 1..) = io::Read::read(&mut from, &mut buf) {
        if to_pacer.send((Instant::now(), buf[..n].to_vec())).is_err() {
            return;
        }
    }
}

/// A [`PacedLine`]'s pacer: writes each chunk to `to` when a line of
/// `byte_s` seconds per byte would have carried its last byte.
fn pace(chunks: Receiver<(Instant, Vec<u8>)>, mut to: File, byte_s: f64, log: Arc<Mutex<LineLog>>) {
    let mut free_at = Instant::now();
    // How long after the aimed-at instant the bytes are in the far end:
    // the thread's wake-up delay (timer slack, scheduling) and the write.
    let mut lead = Duration::ZERO;
    while let Ok((arrived, bytes)) = chunks.recv() {
        let due = free_at.max(arrived) + Duration::from_secs_f64(bytes.len() as f64 * byte_s);
        let aim = due.checked_sub(lead).unwrap_or(due);
        let now = Instant::now();
        let slept = aim > now;
        if slept {
            std::thread::sleep(aim - now);
        }
        if io::Write::write_all(&mut to, &bytes).is_err() {
            return;
        }
        let done = Instant::now();
        if slept {
            let delay = done.saturating_duration_since(aim).min(MAX_LEAD);
            lead = (lead * 7 + delay) / 8;
        }
        let error_ns = if done >= due {
            (done - due).as_nanos() as i64
        } else {
            -((due - done).as_nanos() as i64)
        };
        let mut log = log.lock().unwrap();
        log.bytes += bytes.len() as u64;
        log.error_ns.push(error_ns);
        free_at = due;
    }
}

/// Two pseudo-terminals joined by a [`PacedLine`]: the parties use `near`
/// (or open `near_path`) and `far`.
struct PacedLink {
    line: PacedLine,
    near: SerialStream,
    near_path: String,
    far: SerialStream,
}

fn paced_link(baud: u32, bits: u32) -> PacedLink {
    let near = pty_pair().unwrap();
    let far = pty_pair().unwrap();
    PacedLink {
        line: PacedLine::start(near.host, far.host, baud, bits),
        near: near.device_end,
        near_path: near.device_path,
        far: far.device_end,
    }
}

/// One paced run: its rate, how many operations (bytes, exchanges,
/// polls, frames) it timed, and what the line logged meanwhile.
struct Run {
    rate: f64,
    count: usize,
    logs: [LineLog; 2],
}

/// The relay's byte rate: a sender writes `bytes` bytes as fast as the
/// near pseudo-terminal takes them; the rate is taken at the far end from
/// the first delivery to the last (the first one's latency not counted).
fn line_bytes(bytes: usize) -> Run {
    let rt = Runtime::new().unwrap();
    rt.block_on(async {
        let PacedLink {
            line,
            mut near,
            mut far,
            ..
        } = paced_link(BAUD, BITS_8N1);
        let data = vec![0x55u8; bytes];
        let send = async { near.write_all(&data).await.unwrap() };
        let recv = async {
            let mut buf = vec![0u8; 4096];
            let (mut got, mut first) = (0, None);
            let mut last = Instant::now();
            while got < bytes {
                let n = far.read(&mut buf).await.unwrap();
                last = Instant::now();
                if first.is_none() {
                    first = Some((last, n));
                }
                got += n;
            }
            let (t0, n0) = first.unwrap();
            (got - n0) as f64 / (last - t0).as_secs_f64()
        };
        let ((), rate) = tokio::join!(send, recv);
        Run {
            rate,
            count: bytes,
            logs: line.take(),
        }
    })
}

/// A bare exchange: `out` bytes to an echo at the far end, which answers
/// `back` bytes once it has them all; exchanges per second over
/// `exchanges` (after 20 unmeasured). Through the paced line, or with
/// `paced` false over one pseudo-terminal pair (the software path alone).
fn line_exchange(exchanges: usize, out: usize, back: usize, paced: bool) -> Run {
    let rt = Runtime::new().unwrap();
    rt.block_on(async {
        let (line, mut near, mut far) = if paced {
            let link = paced_link(BAUD, BITS_8N1);
            (Some(link.line), link.near, link.far)
        } else {
            let pty = pty_pair().unwrap();
            (None, pty.host, pty.device_end)
        };
        let take = || line.as_ref().map(PacedLine::take).unwrap_or_default();
        let _echo = tokio::spawn(async move {
            let (mut got, answer) = (vec![0u8; out], vec![0xAAu8; back]);
            while far.read_exact(&mut got).await.is_ok() {
                if far.write_all(&answer).await.is_err() {
                    break;
                }
            }
        });
        let (request, mut answer) = (vec![0x55u8; out], vec![0u8; back]);
        let mut exchange = async || {
            near.write_all(&request).await.unwrap();
            near.read_exact(&mut answer).await.unwrap();
        };
        for _ in 0..20 {
            exchange().await;
        }
        take();
        let t0 = Instant::now();
        for _ in 0..exchanges {
            exchange().await;
        }
        Run {
            rate: exchanges as f64 / t0.elapsed().as_secs_f64(),
            count: exchanges,
            logs: take(),
        }
    })
}

/// The DAQ profile's serial settings for the port at `path`.
fn daq_serial(p: &DeviceProfile, path: &str) -> SerialSettings {
    let s = p
        .serial
        .as_ref()
        .expect("the DAQ profile has serial settings");
    SerialSettings {
        path: path.to_string(),
        baud_rate: s.baud_rate,
        parity: s.parity,
        stop_bits: s.stop_bits,
    }
}

/// Words in the one read request of `regs`.
fn block_words(regs: &[Register]) -> u32 {
    let start = regs.iter().map(|r| r.address).min().unwrap();
    let end = regs
        .iter()
        .map(|r| r.address + r.data_type.width())
        .max()
        .unwrap();
    u32::from(end - start)
}

/// Modbus RTU through the line: the bus task polls the DAQ's three
/// channels (one request) from `serve_rtu` at the far end, `polls` times
/// (after 20 unmeasured, the first of which opens the port).
fn paced_modbus(polls: usize) -> Run {
    let rt = Runtime::new().unwrap();
    let (p, regs) = daq();
    rt.block_on(async {
        let probe = daq_serial(&p, "");
        let link = paced_link(probe.baud_rate, probe.bits_per_byte());
        serve_rtu(link.far, service(&p));
        let bus = spawn_bus(ModbusClient::rtu(
            "bench",
            daq_serial(&p, &link.near_path),
            1,
            policy(),
        ));
        // `link.near` stays open until the end (see `PtyPair`).
        let _near = link.near;
        for _ in 0..20 {
            bus.read(1, regs.clone(), Priority::Routine).await.unwrap();
        }
        link.line.take();
        let t0 = Instant::now();
        for _ in 0..polls {
            bus.read(1, regs.clone(), Priority::Routine).await.unwrap();
        }
        Run {
            rate: polls as f64 / t0.elapsed().as_secs_f64(),
            count: polls,
            logs: link.line.take(),
        }
    })
}

/// The frame of the SLCAN benches: standard id, 8 bytes.
fn can_frame() -> CanFrame {
    CanFrame::new(CanId::Standard(0x181), &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap()
}

/// SLCAN through the line: `frames` eight-byte standard frames from one
/// `SlcanStream` to another (`send` waits for no answer; `ack_timeout:
/// None` because the peer does not answer the setup commands either);
/// frames per second at the receiver from its first frame to its last
/// (after 20 unmeasured).
fn paced_slcan(frames: usize) -> Run {
    let rt = Runtime::new().unwrap();
    let opts = SlcanOptions {
        ack_timeout: None,
        ..SlcanOptions::default()
    };
    let frame = can_frame();
    rt.block_on(async {
        let link = paced_link(BAUD, BITS_8N1);
        let mut tx = SlcanStream::open(link.near, "tx", opts).await.unwrap();
        let mut rx = SlcanStream::open(link.far, "rx", opts).await.unwrap();
        for _ in 0..20 {
            tx.send(&frame).await.unwrap();
            rx.recv().await.unwrap();
        }
        link.line.take();
        let send = async {
            for _ in 0..frames {
                tx.send(&frame).await.unwrap();
            }
        };
        let recv = async {
            rx.recv().await.unwrap();
            let t0 = Instant::now();
            for _ in 1..frames {
                rx.recv().await.unwrap();
            }
            (frames - 1) as f64 / t0.elapsed().as_secs_f64()
        };
        let ((), rate) = tokio::join!(send, recv);
        Run {
            rate,
            count: frames,
            logs: link.line.take(),
        }
    })
}

/// Mean error of a [`PacedLine`]'s deliveries above which a run is
/// flagged: the relay did not keep time (a busy machine starves its
/// threads), and the rate measured is the machine's, not the link's.
const LATE_US: f64 = 50.0;

/// The deliveries' errors against the line clock, both directions, in µs,
/// sorted.
fn errors_us(logs: &[LineLog]) -> Vec<f64> {
    let mut e: Vec<f64> = logs
        .iter()
        .flat_map(|l| l.error_ns.iter().map(|&ns| ns as f64 / 1e3))
        .collect();
    e.sort_by(f64::total_cmp);
    e
}

/// The deliveries' errors: mean, median, 1st and 99th percentile.
fn error_summary(logs: &[LineLog]) -> String {
    let e = errors_us(logs);
    if e.is_empty() {
        return "no deliveries".into();
    }
    let at = |q: f64| e[((e.len() - 1) as f64 * q).round() as usize];
    let mean = e.iter().sum::<f64>() / e.len() as f64;
    format!(
        "{} deliveries, error mean {mean:+.1} µs, median {:+.1}, p1 {:+.1}, p99 {:+.1}",
        e.len(),
        at(0.5),
        at(0.01),
        at(0.99)
    )
}

/// Run `measure` `repeats` times, print each run, and return the median
/// rate and the runs' range.
fn runs(name: &str, unit: &str, repeats: usize, measure: impl Fn() -> Run) -> (f64, f64, f64) {
    let (mut rates, mut late) = (Vec::new(), 0);
    for k in 1..=repeats {
        let run = measure();
        let e = errors_us(&run.logs);
        if !e.is_empty() && e.iter().sum::<f64>() / e.len() as f64 > LATE_US {
            late += 1;
        }
        let [ab, ba] = &run.logs;
        let per = |bytes: u64| bytes as f64 / run.count as f64;
        println!(
            "bus_limits {name} run {k}/{repeats}: {:.1} {unit}/s over {} {unit}; line carried \
             {} bytes out and {} back ({:.1} and {:.1} per {}); {}",
            run.rate,
            run.count,
            ab.bytes,
            ba.bytes,
            per(ab.bytes),
            per(ba.bytes),
            unit.trim_end_matches('s'),
            error_summary(&run.logs)
        );
        rates.push(run.rate);
    }
    if late > 0 {
        println!(
            "bus_limits {name}: WARNING: in {late} of {repeats} runs the line's deliveries were \
             late by more than {LATE_US} µs on average: the machine was too busy for the relay \
             to keep time, and those rates are low for that reason"
        );
    }
    rates.sort_by(f64::total_cmp);
    (rates[rates.len() / 2], rates[0], rates[rates.len() - 1])
}

/// Print `ratio <name> <measured/limit> limit=<x>/s measured=<y>/s`.
fn ratio(name: &str, measured: f64, limit: f64) {
    println!(
        "ratio {name} {:.3} limit={limit:.1}/s measured={measured:.1}/s",
        measured / limit
    );
}

/// Criterion options that take a value (criterion 0.8's command line).
const VALUE_OPTIONS: &[&str] = &[
    "-c",
    "--color",
    "--colour",
    "-s",
    "--save-baseline",
    "-b",
    "--baseline",
    "--baseline-lenient",
    "--load-baseline",
    "--format",
    "--profile-time",
    "--sample-size",
    "--warm-up-time",
    "--measurement-time",
    "--nresamples",
    "--noise-threshold",
    "--confidence-level",
    "--significance-level",
    "--plotting-backend",
    "--output-format",
];

/// How much of the paced measurements the command line asks for.
#[derive(Debug, PartialEq)]
enum Paced {
    /// A filter that does not match `bus_limits`.
    Skip,
    /// `--list`: name them only.
    List,
    /// `--test` (`cargo test --benches`): one short run of each.
    Test,
    /// Everything.
    Full,
}

/// Criterion keeps its filter to itself, so the command line is read here
/// the way criterion reads it: the first argument that is neither an
/// option nor an option's value is the filter, matched as a substring.
fn paced_mode() -> Paced {
    let (mut filter, mut test, mut list) = (None, false, false);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if VALUE_OPTIONS.contains(&a.as_str()) {
            args.next();
        } else if a == "--test" {
            test = true;
        } else if a == "--list" {
            list = true;
        } else if !a.starts_with('-') && filter.is_none() {
            filter = Some(a);
        }
    }
    match filter {
        Some(f) if !"bus_limits".contains(f.as_str()) => Paced::Skip,
        _ if list => Paced::List,
        _ if test => Paced::Test,
        _ => Paced::Full,
    }
}

fn bus_limits(_: &mut Criterion) {
    let (repeats, scale) = match paced_mode() {
        Paced::Skip => return,
        Paced::List => {
            println!("bus_limits: benchmark");
            return;
        }
        Paced::Test => (1, 50),
        Paced::Full => (REPEATS, 1),
    };
    let byte_rate = f64::from(BAUD) / f64::from(BITS_8N1);
    let (p, regs) = daq();
    let words = block_words(&regs);

    // The relay itself: a free-running sender, then a bare exchange of the
    // RTU poll's sizes.
    let (m, lo, hi) = runs("line_bytes", "bytes", repeats, || {
        line_bytes(2 * BAUD as usize / BITS_8N1 as usize / scale)
    });
    println!("bus_limits line_bytes: median {m:.1} bytes/s (runs {lo:.1}–{hi:.1})");
    ratio("line_bytes", m, byte_rate);
    let (out, back) = (8, 5 + 2 * words as usize);
    let name = format!("line_exchange_{out}_{back}");
    let (m, lo, hi) = runs(&name, "exchanges", repeats, || {
        line_exchange(2000 / scale, out, back, true)
    });
    println!("bus_limits {name}: median {m:.1} exchanges/s (runs {lo:.1}–{hi:.1})");
    ratio(&name, m, byte_rate / (out + back) as f64);
    let (u, ulo, uhi) = runs("pty_exchange", "exchanges", repeats, || {
        line_exchange(20_000 / scale, out, back, false)
    });
    let line_us = (out + back) as f64 / byte_rate * 1e6;
    let over_us = 1e6 / m - line_us;
    println!(
        "bus_limits pty_exchange (one pseudo-terminal pair, no relay): median {u:.0} exchanges/s \
         (runs {ulo:.0}–{uhi:.0}). Through the line an exchange took {:.0} µs: {line_us:.0} µs \
         of line time and {over_us:.0} µs more, of which {:.0} µs is the software path back to \
         back without the relay and {:.0} µs the relay's two reader wake-ups and the parties' \
         wake-ups from idle",
        1e6 / m,
        1e6 / u,
        over_us - 1e6 / u
    );

    // Modbus RTU: the DAQ's block at the profile's line settings.
    let s = daq_serial(&p, "");
    let (baud, bits) = (f64::from(s.baud_rate), f64::from(s.bits_per_byte()));
    let (m, lo, hi) = runs("modbus_rtu", "polls", repeats, || {
        paced_modbus(2000 / scale)
    });
    let line_us = f64::from(13 + 2 * words) * bits / baud * 1e6;
    println!(
        "bus_limits modbus_rtu: {words}-register read at {baud} baud, {bits} bits per byte: \
         median {m:.1} polls/s (runs {lo:.1}–{hi:.1}); a poll took {:.0} µs: {line_us:.0} µs of \
         line time and {:.0} µs more",
        1e6 / m,
        1e6 / m - line_us
    );
    // The silence the client keeps before each request (the spec's).
    let gap = rtu_frame_gap(&s).as_secs_f64();
    ratio("modbus_rtu", m, rtu_limit(words, baud, bits, gap));
    ratio(
        "modbus_rtu_3_5_characters",
        m,
        rtu_limit(words, baud, bits, 3.5 * bits / baud),
    );
    ratio(
        "modbus_rtu_no_silence",
        m,
        rtu_limit(words, baud, bits, 0.0),
    );

    // SLCAN: 8-byte standard frames.
    let chars = encode_frame(&can_frame()).len() as f64;
    let (m, lo, hi) = runs("slcan", "frames", repeats, || paced_slcan(5000 / scale));
    println!(
        "bus_limits slcan: {chars}-character frames at {BAUD} baud: median {m:.1} frames/s \
         (runs {lo:.1}–{hi:.1})"
    );
    ratio("slcan", m, byte_rate / chars);
}

criterion_group! {
    name = links;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    targets = modbus, slcan
}
criterion_group!(paced, bus_limits);
criterion_main!(links, paced);
