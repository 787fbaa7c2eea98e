//! Sustained rates of the links, on this machine (loopback and
//! pseudo-terminals, no hardware):
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
//!
//! `cargo bench --bench links`; rates are 1 / (time per iteration), ×1000
//! for the frame burst.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use motorbench_drivers::can::{CanFrame, CanId, FrameStream, SlcanOptions, SlcanStream};
use motorbench_drivers::modbus::server::{
    serve_rtu, serve_tcp, BankService, PassiveDevice, RegisterBank,
};
use motorbench_drivers::modbus::{
    read_registers, spawn_bus, CallPolicy, DeviceProfile, ModbusClient, Priority, Register,
};
use motorbench_drivers::serial::port::{open_serial, pty_pair, SerialSettings};
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
    let frame = CanFrame::new(CanId::Standard(0x181), &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
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

criterion_group! {
    name = links;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    targets = modbus, slcan
}
criterion_main!(links);
