//! SocketCAN on the Linux kernel's virtual CAN interface `vcan0`.
//!
//! The round trip needs a kernel with CAN and a `vcan0` interface
//! (`ip link add dev vcan0 type vcan && ip link set vcan0 up`); it is
//! `#[ignore]`d so that `cargo test` reports it as *ignored*, never as
//! passed, where the kernel has no CAN. `tests/run.sh` runs it with
//! `--ignored` when `vcan0` exists and otherwise prints that it did not run.

use std::time::Duration;

use motorbench_drivers::can::{CanFrame, CanId, FrameStream, SocketCanStream};

fn vcan0_present() -> bool {
    std::path::Path::new("/sys/class/net/vcan0").exists()
}

#[tokio::test]
#[ignore = "needs kernel CAN and a vcan0 interface; tests/run.sh runs it where vcan0 exists"]
async fn frames_round_trip_on_vcan0() {
    let mut a = SocketCanStream::open("vcan0").unwrap();
    let mut b = SocketCanStream::open("vcan0").unwrap();
    let frames = [
        CanFrame::new(CanId::Standard(0x181), &[1, 2, 3, 4]).unwrap(),
        CanFrame::new(CanId::Extended(0x18FF_0001), &[0xFF; 8]).unwrap(),
        CanFrame::remote(CanId::Standard(0x701), 1).unwrap(),
    ];
    for f in &frames {
        a.send(f).await.unwrap();
        let got = tokio::time::timeout(Duration::from_secs(5), b.recv())
            .await
            .expect("the frame arrives")
            .unwrap();
        assert_eq!(&got, f);
    }
}

/// Without kernel CAN, opening fails as a link failure that names the
/// interface (the error a user sees on a machine without CAN).
#[test]
fn opening_a_missing_interface_is_a_link_error_naming_it() {
    if vcan0_present() {
        // The interface exists here: opening must succeed instead.
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let _guard = rt.enter();
        SocketCanStream::open("vcan0").unwrap();
        return;
    }
    let err = SocketCanStream::open("vcan0").unwrap_err();
    assert!(err.is_link_failure(), "{err}");
    let text = err.to_string();
    assert!(
        text.contains("vcan0") && text.contains("SocketCAN"),
        "{text}"
    );
}
