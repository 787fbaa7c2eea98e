//! The Modbus client, power stage and register maps against pymodbus, a
//! server nobody here wrote: over TCP on 127.0.0.1 (a port the peer's OS
//! picked) and over RTU on a pseudo-terminal pair.

use crate::common;

use std::path::Path;
use std::time::Duration;

use common::peer::Peer;
use motorbench_drivers::modbus::{
    spawn_bus, BusHandle, CallPolicy, DataType, DeviceProfile, ModbusClient, ModbusPowerStage,
    Priority, Register, RegisterKind,
};
use motorbench_drivers::serial::port::pty_pair;
use motorbench_drivers::{DriverError, PowerStage};

fn riden() -> DeviceProfile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/devices/riden-rd6006.toml");
    DeviceProfile::load(&path).unwrap()
}

fn float_input(address: u16) -> Register {
    Register {
        name: format!("f{address}"),
        address,
        kind: RegisterKind::Input,
        data_type: DataType::F32,
        scale: 1.0,
        offset: 0.0,
        unit: "V".into(),
        access: Default::default(),
        word_order: Default::default(),
        byte_order: Default::default(),
    }
}

fn holding(p: &DeviceProfile, name: &str) -> Register {
    p.register(name).unwrap().clone()
}

async fn raw(bus: &BusHandle, address: u16) -> f64 {
    let mut r = float_input(address);
    r.kind = RegisterKind::Holding;
    r.data_type = DataType::U16;
    bus.read(1, vec![r], Priority::Routine)
        .await
        .unwrap()
        .values[0]
}

/// The checks both transports go through.
async fn exercise(bus: &BusHandle) {
    let p = riden();
    // Reads: a u16 and two big-endian floats encoded by the peer.
    let model = bus
        .read(1, vec![holding(&p, "model_id")], Priority::Routine)
        .await
        .unwrap();
    assert_eq!(model.values, vec![60062.0]);
    let f = bus
        .read(1, vec![float_input(2), float_input(0)], Priority::Routine)
        .await
        .unwrap();
    assert_eq!(f.values, vec![-1.25, 230.5]);

    // The power stage writes through the profile's registers.
    let mut stage = ModbusPowerStage::new("rd6006", bus.clone(), 1, &p).unwrap();
    stage.set_setpoint(12.34).await.unwrap();
    stage.set_current_limit(1.5).await.unwrap();
    stage.set_output_enabled(true).await.unwrap();
    assert_eq!(raw(bus, 8).await, 1234.0, "0.01 V per count");
    assert_eq!(raw(bus, 9).await, 1500.0, "0.001 A per count");
    assert_eq!(raw(bus, 18).await, 1.0);
    let err = stage.set_setpoint(61.0).await.unwrap_err();
    assert!(matches!(err, DriverError::Device { .. }), "{err}");
    assert_eq!(raw(bus, 8).await, 1234.0, "a refused set point is not sent");
    stage.safe_state().await.unwrap();
    assert_eq!(raw(bus, 18).await, 0.0);
    assert_eq!(raw(bus, 8).await, 0.0);

    // An address the device does not have: the device's exception, kept
    // apart from link failures.
    let mut beyond = holding(&p, "model_id");
    beyond.address = 200;
    let err = bus
        .read(1, vec![beyond], Priority::Routine)
        .await
        .unwrap_err();
    assert!(!err.is_link_failure(), "{err}");
    assert!(err.to_string().contains("0x02"), "{err}");
}

fn policy() -> CallPolicy {
    CallPolicy {
        timeout: Duration::from_millis(500),
        retries: 1,
        retry_delay: Duration::from_millis(10),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcp_client_against_pymodbus_server() {
    let mut peer = Peer::start("modbus_peer.py", &["tcp"]);
    let port: u16 = peer.ready().parse().unwrap();
    let addr = format!("127.0.0.1:{port}").parse().unwrap();
    let bus = spawn_bus(ModbusClient::tcp("pymodbus-tcp", addr, 1, policy()));
    exercise(&bus).await;

    // Pull the cable: the next call fails as a link failure, not as a
    // device exception.
    peer.kill();
    let err = bus
        .read(1, vec![holding(&riden(), "model_id")], Priority::Routine)
        .await
        .unwrap_err();
    assert!(err.is_link_failure(), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rtu_client_against_pymodbus_server_on_a_pty() {
    let pty = pty_pair().unwrap();
    let mut peer = Peer::start("modbus_peer.py", &["rtu", &pty.device_path, "115200"]);
    peer.ready();
    let bus = spawn_bus(ModbusClient::attach_rtu(
        "pymodbus-rtu",
        pty.host,
        1,
        policy(),
    ));
    exercise(&bus).await;

    // A unit id the peer does not serve: pymodbus 3.16.1 answers with
    // exception 0x04 (its device lookup fails inside the server) where a
    // real RS-485 line would stay silent. Whatever the device answers is a
    // device error, not a link failure.
    let err = bus
        .read(7, vec![holding(&riden(), "model_id")], Priority::Routine)
        .await
        .unwrap_err();
    assert!(matches!(err, DriverError::Device { .. }), "{err}");

    peer.kill();
    let err = bus
        .read(1, vec![holding(&riden(), "model_id")], Priority::Routine)
        .await
        .unwrap_err();
    assert!(err.is_link_failure(), "{err}");
    drop(pty.device_end);
}
