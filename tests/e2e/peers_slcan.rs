//! SLCAN over a pseudo-terminal against python-can's slcan interface (the
//! host side of the Lawicel protocol, written by others).

use crate::common;

use std::time::Duration;

use common::peer::Peer;
use motorbench_drivers::can::{
    CanFrame, CanId, FrameStream, SlcanBitrate, SlcanOptions, SlcanStream,
};
use motorbench_drivers::serial::port::pty_pair;

fn opts() -> SlcanOptions {
    // python-can is a host, not an adapter: it does not answer commands.
    SlcanOptions {
        bitrate: Some(SlcanBitrate::K500),
        listen_only: false,
        ack_timeout: None,
    }
}

async fn recv(s: &mut impl FrameStream) -> CanFrame {
    tokio::time::timeout(Duration::from_secs(20), s.recv())
        .await
        .expect("a frame arrives")
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_can_echoes_every_kind_of_frame() {
    let pty = pty_pair().unwrap();
    let mut peer = Peer::start("slcan_peer.py", &[&pty.device_path, "echo"]);
    peer.ready();
    let mut s = SlcanStream::open(pty.host, "slcan-pty", opts())
        .await
        .unwrap();
    let frames = vec![
        CanFrame::new(CanId::Standard(0x000), &[]).unwrap(),
        CanFrame::new(
            CanId::Standard(0x181),
            &[0xA0, 0x86, 0x01, 0x00, 0x24, 0xFA],
        )
        .unwrap(),
        CanFrame::new(CanId::Standard(0x7FE), &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap(),
        CanFrame::new(CanId::Extended(0x18FF_0001), &[0xFF; 8]).unwrap(),
        CanFrame::new(CanId::Extended(0x1FFF_FFFE), &[0x00]).unwrap(),
        CanFrame::remote(CanId::Standard(0x701), 1).unwrap(),
    ];
    for f in &frames {
        s.send(f).await.unwrap();
        let echo = recv(&mut s).await;
        let id = match f.id() {
            CanId::Standard(v) => CanId::Standard(v + 1),
            CanId::Extended(v) => CanId::Extended(v + 1),
        };
        assert_eq!(echo.id(), id, "{f:?}");
        assert_eq!(echo.data(), f.data(), "{f:?}");
        assert_eq!(echo.is_remote(), f.is_remote(), "{f:?}");
        assert_eq!(echo.dlc(), f.dlc(), "{f:?}");
    }
    assert_eq!(s.malformed(), 0);
    peer.close_stdin();
    drop(pty.device_end);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_burst_from_python_can_arrives_whole_and_in_order() {
    let pty = pty_pair().unwrap();
    let mut peer = Peer::start("slcan_peer.py", &[&pty.device_path, "burst", "2000"]);
    peer.ready();
    let mut s = SlcanStream::open(pty.host, "slcan-pty", opts())
        .await
        .unwrap();
    for k in 0u32..2000 {
        let f = recv(&mut s).await;
        assert_eq!(f.id(), CanId::Standard(0x181));
        assert_eq!(&f.data()[..4], &k.to_le_bytes(), "frame {k}");
        assert_eq!(&f.data()[4..], &[0xA5, 0x5A, 0x00, 0xFF]);
    }
    assert_eq!(peer.line(), "DONE 2000");
    assert_eq!(s.malformed(), 0);
    peer.close_stdin();
    drop(pty.device_end);
}
