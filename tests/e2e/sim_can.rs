//! The simulated CANopen (CiA 406) encoder behind SLCAN on a
//! pseudo-terminal: its TPDOs, encoded with the shipped DBC file, are
//! decoded on the bench side by the DBC signal map and agree with the
//! encoder count the simulated DAQ reports over Modbus.

use std::path::Path;
use std::time::Duration;

use motorbench::config::Config;
use motorbench::machine::dc::build_rig;
use motorbench_drivers::can::{CanChannel, CanSignalSensors, SignalMap, SlcanOptions, SlcanStream};
use motorbench_drivers::serial::port::{open_serial, pty_pair, SerialSettings};
use motorbench_drivers::{ChannelInfo, SensorStream};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn simulated_can_encoder_agrees_with_the_daq_count() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cfg = Config::load(&root.join("config/sim-modbus-dc.toml")).unwrap();
    let dbc_path = root.join("config/devices/cia406-encoder.dbc");
    let map = SignalMap::parse(
        &dbc_path.display().to_string(),
        &std::fs::read_to_string(&dbc_path).unwrap(),
    )
    .unwrap();
    let mut rig = build_rig(&cfg, false).await.unwrap();

    // The encoder's side of the SLCAN link, and the bench's.
    let pty = pty_pair().unwrap();
    let opts = SlcanOptions {
        ack_timeout: None,
        ..SlcanOptions::default()
    };
    let encoder_side = SlcanStream::open(pty.host, "sim-encoder", opts)
        .await
        .unwrap();
    rig.served
        .as_mut()
        .unwrap()
        .start_can_encoder(Box::new(encoder_side), map.clone(), 500.0)
        .unwrap();
    let port = open_serial(&SerialSettings::new_8n1(&pty.device_path, 115_200)).unwrap();
    let bench_side = SlcanStream::open(port, "can-pty", opts).await.unwrap();
    let mut can = CanSignalSensors::new(
        "cia406",
        bench_side,
        map,
        vec![CanChannel {
            signal: "position".into(),
            info: ChannelInfo {
                quantity: "encoder_count".into(),
                unit: "count".into(),
                source: "can:cia406".into(),
                rate_hz: 500.0,
            },
        }],
    )
    .unwrap();

    rig.stage.set_current_limit(2.0).await.unwrap();
    rig.stage.set_setpoint(30.0).await.unwrap();
    rig.stage.set_output_enabled(true).await.unwrap();
    let mut last = 0.0;
    for _ in 0..400 {
        let b = tokio::time::timeout(Duration::from_secs(5), can.next_batch())
            .await
            .expect("the encoder streams")
            .unwrap();
        let p = b.samples[0].value;
        assert!(p >= last, "the motor turns one way: {p} after {last}");
        last = p;
    }
    assert!(last > 1000.0, "the motor turned: {last}");
    // The DAQ's count over Modbus, read right after, agrees (the motor
    // turns ~35 counts per ms at 30 V; allow a few ms between the reads).
    let probe = rig.modbus_sensors.as_ref().unwrap();
    let daq = probe.read_each().await;
    let (_, count) = daq
        .iter()
        .find(|(c, _)| c.quantity == "encoder_count")
        .unwrap();
    let count = *count.as_ref().unwrap();
    assert!((count - last).abs() < 1000.0, "CAN {last}, DAQ {count}");
    rig.stage.safe_state().await.unwrap();
    let stats = can.sampling_stats();
    assert_eq!(stats[0].received, 400);
    drop(pty.device_end);
}
