//! The serial sensor protocols against pyserial on a pseudo-terminal: the
//! peer encodes records from the protocols' written definitions, with
//! noise, corrupted records and one missing record.

use crate::common;

use std::time::Duration;

use common::peer::Peer;
use motorbench_drivers::serial::port::pty_pair;
use motorbench_drivers::serial::{SerialChannel, SerialFraming, SerialSensors};
use motorbench_drivers::{ChannelInfo, SensorStream};

const COUNT: u32 = 300;
const SKIPPED: u32 = 57;

fn channels(keys: [&str; 3]) -> Vec<SerialChannel> {
    keys.iter()
        .zip(["armature_voltage", "armature_current", "encoder_count"])
        .map(|(k, q)| SerialChannel {
            key: k.to_string(),
            info: ChannelInfo {
                quantity: q.into(),
                unit: "V".into(),
                source: "pyserial".into(),
                rate_hz: 2000.0,
            },
        })
        .collect()
}

async fn receive(framing: SerialFraming, name: &str, keys: [&str; 3]) {
    let pty = pty_pair().unwrap();
    let mut s = SerialSensors::new("pyserial", pty.host, framing, channels(keys));
    let count = COUNT.to_string();
    let skip = SKIPPED.to_string();
    let mut peer = Peer::start(
        "serial_peer.py",
        &[
            &pty.device_path,
            name,
            &count,
            "--garbage",
            "--skip",
            &skip,
            "--hold",
        ],
    );
    let mut first_t = None;
    for k in (1..=COUNT).filter(|&k| k != SKIPPED) {
        let b = tokio::time::timeout(Duration::from_secs(20), s.next_batch())
            .await
            .expect("the peer streams")
            .unwrap();
        let t0 = *first_t.get_or_insert(b.t_ns);
        // Device time: 500 µs per sequence number.
        assert_eq!(b.t_ns - t0, u64::from(k - 1) * 500_000, "record {k}");
        let v: Vec<f64> = b.samples.iter().map(|s| s.value).collect();
        let kf = f64::from(k);
        assert_eq!(
            v,
            vec![0.5 * kf, -kf / 1000.0, kf * 1_000_003.0],
            "record {k}"
        );
    }
    assert_eq!(peer.line(), format!("DONE {COUNT}"));
    let stats = s.sampling_stats();
    for c in &stats {
        assert_eq!((c.received, c.lost), (u64::from(COUNT) - 1, 1), "{c}");
        assert!(c.jitter_max_s < 1e-12, "device clock: no jitter: {c}");
    }
    // One corrupted copy before every tenth record, all refused.
    assert_eq!(s.decode_counts().rejected, u64::from(COUNT / 10));
    let warnings = s.take_warnings().join("\n");
    assert!(
        warnings.contains(&format!(
            "1 record(s) lost before sequence number {}",
            SKIPPED + 1
        )),
        "{warnings}"
    );
    peer.close_stdin();
    drop(pty.device_end);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ascii_lines_from_pyserial_with_garbage() {
    receive(SerialFraming::Ascii, "ascii", ["u", "i", "n"]).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cobs_frames_from_pyserial_with_garbage() {
    receive(SerialFraming::Binary, "binary", ["0", "1", "2"]).await;
}
