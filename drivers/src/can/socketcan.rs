//! SocketCAN: CAN interfaces of the Linux kernel (`can0`, `vcan0`), through
//! the `socketcan` crate's tokio socket.
//!
//! Compiled everywhere; it works only where the kernel has CAN support and
//! the interface exists (opening fails with "No such device" or "Address
//! family not supported by protocol" otherwise).

use async_trait::async_trait;
use socketcan::{EmbeddedFrame, ExtendedId, Id, StandardId};

use super::{CanFrame, CanId, FrameStream};
use crate::DriverError;

/// A kernel CAN interface.
pub struct SocketCanStream {
    name: String,
    socket: socketcan::tokio::CanSocket,
}

impl std::fmt::Debug for SocketCanStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SocketCanStream")
            .field("name", &self.name)
            .finish()
    }
}

impl SocketCanStream {
    /// Open the interface `ifname` (e.g. `can0`).
    pub fn open(ifname: &str) -> Result<SocketCanStream, DriverError> {
        let socket = socketcan::tokio::CanSocket::open(ifname).map_err(|e| DriverError::Link {
            device: ifname.to_string(),
            reason: format!("cannot open SocketCAN interface: {e}"),
        })?;
        Ok(SocketCanStream {
            name: ifname.to_string(),
            socket,
        })
    }
}

/// Our frame as a socketcan frame.
pub(crate) fn to_socketcan(frame: &CanFrame) -> Option<socketcan::CanFrame> {
    let id: Id = match frame.id() {
        CanId::Standard(v) => StandardId::new(v)?.into(),
        CanId::Extended(v) => ExtendedId::new(v)?.into(),
    };
    if frame.is_remote() {
        socketcan::CanFrame::new_remote(id, usize::from(frame.dlc()))
    } else {
        socketcan::CanFrame::new(id, frame.data())
    }
}

/// A socketcan frame as ours; `None` for error frames.
pub(crate) fn from_socketcan(frame: &socketcan::CanFrame) -> Option<CanFrame> {
    if matches!(frame, socketcan::CanFrame::Error(_)) {
        return None;
    }
    let id = match frame.id() {
        Id::Standard(s) => CanId::Standard(s.as_raw()),
        Id::Extended(e) => CanId::Extended(e.as_raw()),
    };
    if frame.is_remote_frame() {
        CanFrame::remote(id, frame.dlc() as u8).ok()
    } else {
        CanFrame::new(id, frame.data()).ok()
    }
}

#[async_trait]
impl FrameStream for SocketCanStream {
    fn id(&self) -> &str {
        &self.name
    }

    async fn send(&mut self, frame: &CanFrame) -> Result<(), DriverError> {
        let f = to_socketcan(frame).ok_or_else(|| DriverError::Device {
            device: self.name.clone(),
            reason: format!("frame {frame:?} cannot be expressed"),
        })?;
        self.socket
            .write_frame(f)
            .await
            .map_err(|e| DriverError::Link {
                device: self.name.clone(),
                reason: e.to_string(),
            })
    }

    async fn recv(&mut self) -> Result<CanFrame, DriverError> {
        loop {
            let f = self
                .socket
                .read_frame()
                .await
                .map_err(|e| DriverError::Link {
                    device: self.name.clone(),
                    reason: e.to_string(),
                })?;
            if let Some(frame) = from_socketcan(&f) {
                return Ok(frame);
            }
            // Error frames carry bus state, not data: skipped here.
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_convert_both_ways_without_a_kernel() {
        for f in [
            CanFrame::new(CanId::Standard(0x181), &[1, 2, 3]).unwrap(),
            CanFrame::new(CanId::Extended(0x18FF_0001), &[0; 8]).unwrap(),
            CanFrame::remote(CanId::Standard(0x701), 1).unwrap(),
        ] {
            let s = to_socketcan(&f).unwrap();
            assert_eq!(from_socketcan(&s).unwrap(), f);
        }
    }
}
