//! The Modbus power stage and block reads against the in-process register
//! bank server: the heartbeat register is written by itself, a refused
//! write is a device error, and registers are read together only where the
//! addresses between them may be read.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use motorbench_drivers::modbus::server::{
    lock_bank, serve_tcp, BankService, ExceptionCode, PassiveDevice, RegisterBank, SimulatedDevice,
    WriteSpan,
};
use motorbench_drivers::modbus::{
    read_registers, spawn_bus, CallPolicy, DeviceProfile, ModbusClient, ModbusPowerStage,
};
use motorbench_drivers::{DriverError, PowerStage};

const PROFILE: &str = r#"
[device]
name = "test drive"
role = "vfd"
source = "made up for a test"
verification = "none"

[modbus]
unit_id = 3

[registers.control]
address = 0
kind = "holding"
type = "u16"
access = "read_write"

[registers.speed_set]
address = 1
kind = "holding"
type = "i16"
scale = 0.1
unit = "Hz"
access = "read_write"

[registers.watchdog]
address = 2
kind = "holding"
type = "u16"
access = "read_write"

[power_stage]
setpoint = "speed_set"
enable = "control"
enable_value = 1
disable_value = 8
max_setpoint = 100
heartbeat = "watchdog"
heartbeat_period_ms = 20
"#;

async fn server(
    profile: &DeviceProfile,
    device: Arc<dyn SimulatedDevice>,
) -> (std::net::SocketAddr, Arc<Mutex<RegisterBank>>) {
    let bank = Arc::new(Mutex::new(RegisterBank::for_profile(profile)));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let (addr, _task) = serve_tcp(
        listener,
        BankService::new(profile.unit_id, bank.clone(), device),
    )
    .unwrap();
    (addr, bank)
}

/// Refuses set points above 50 Hz, as a drive refuses one above its
/// maximum frequency parameter.
struct FiftyHertzDrive;

impl SimulatedDevice for FiftyHertzDrive {
    fn after_write(
        &self,
        bank: &mut RegisterBank,
        _before: &RegisterBank,
        span: WriteSpan,
    ) -> Result<(), ExceptionCode> {
        if span.address <= 1 && bank.holding[&1] as i16 > 500 {
            return Err(ExceptionCode::IllegalDataValue);
        }
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_stage_drives_its_registers_and_beats_its_heart() {
    let p = DeviceProfile::parse("test.toml", PROFILE).unwrap();
    let (addr, bank) = server(&p, Arc::new(FiftyHertzDrive)).await;
    let bus = spawn_bus(ModbusClient::tcp("drive", addr, 3, CallPolicy::default()));
    let mut stage = ModbusPowerStage::new("drive", bus, 3, &p).unwrap();

    stage.set_setpoint(-12.5).await.unwrap();
    stage.set_output_enabled(true).await.unwrap();
    {
        let b = lock_bank(&bank);
        assert_eq!(b.holding[&1] as i16, -125, "i16 at 0.1 Hz");
        assert_eq!(b.holding[&0], 1);
    }
    // Above what the device accepts: its exception, kept as a device error,
    // and the register keeps its value.
    let err = stage.set_setpoint(60.0).await.unwrap_err();
    assert!(matches!(err, DriverError::Device { .. }), "{err}");
    assert!(err.to_string().contains("0x03"), "{err}");
    assert_eq!(lock_bank(&bank).holding[&1] as i16, -125);
    // Above the profile's limit: refused before it is sent.
    let err = stage.set_setpoint(150.0).await.unwrap_err();
    assert!(err.to_string().contains("outside ±100"), "{err}");

    // The heartbeat counts up by itself (waiting with a generous guard, not
    // timing it).
    tokio::time::timeout(Duration::from_secs(10), async {
        while lock_bank(&bank).holding[&2] < 3 {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    })
    .await
    .expect("the heartbeat register is written");
    assert_eq!(stage.heartbeat_failures(), 0);

    stage.safe_state().await.unwrap();
    let b = lock_bank(&bank);
    assert_eq!(
        b.holding[&0], 8,
        "the profile's disable value (a coast stop)"
    );
    assert_eq!(b.holding[&1], 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reads_span_undefined_addresses_only_where_the_profile_allows() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/devices/eastron-sdm630.toml");
    let p = DeviceProfile::load(&path).unwrap();
    let (addr, bank) = server(&p, Arc::new(PassiveDevice)).await;
    let regs: Vec<_> = [
        "phase1_voltage",
        "phase1_current",
        "total_power",
        "line12_voltage",
    ]
    .iter()
    .map(|n| p.register(n).unwrap().clone())
    .collect();
    {
        let mut b = lock_bank(&bank);
        for (r, v) in regs.iter().zip([230.5, 4.25, 2940.0, 399.0]) {
            b.set(r, v);
        }
    }
    let mut client = ModbusClient::tcp("meter", addr, 1, CallPolicy::default());
    // Adjacent only (the default): four requests, none touching an
    // address the device does not define.
    let values = read_registers(&mut client, &regs, 0).await.unwrap();
    assert_eq!(values, vec![230.5, 4.25, 2940.0, 399.0]);
    assert_eq!(client.stats().calls, 4);
    // Spanning the gaps of a device that allows it: the addresses between
    // exist; 0, 6 and 52 fit one request, 200 needs a second one.
    {
        let mut b = lock_bank(&bank);
        for a in 0..210 {
            b.input.entry(a).or_insert(0);
        }
    }
    let values = read_registers(&mut client, &regs, 60).await.unwrap();
    assert_eq!(values, vec![230.5, 4.25, 2940.0, 399.0]);
    assert_eq!(client.stats().calls, 4 + 2);
}
