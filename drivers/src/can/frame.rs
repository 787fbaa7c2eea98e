//! A classic CAN 2.0 frame, independent of any backend.

use std::fmt;

/// A CAN identifier: 11-bit standard or 29-bit extended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CanId {
    /// 11-bit identifier (0..=0x7FF).
    Standard(u16),
    /// 29-bit identifier (0..=0x1FFF_FFFF).
    Extended(u32),
}

impl CanId {
    /// The raw identifier value, without any extended-frame flag.
    pub fn raw(self) -> u32 {
        match self {
            CanId::Standard(id) => u32::from(id),
            CanId::Extended(id) => id,
        }
    }

    /// True for a 29-bit identifier.
    pub fn is_extended(self) -> bool {
        matches!(self, CanId::Extended(_))
    }
}

impl fmt::Display for CanId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CanId::Standard(id) => write!(f, "{id:03X}"),
            CanId::Extended(id) => write!(f, "{id:08X}"),
        }
    }
}

/// Why a frame could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The identifier does not fit its format.
    #[error("CAN id {0:#X} out of range for its format")]
    IdOutOfRange(u32),
    /// More than 8 data bytes (classic CAN).
    #[error("{0} data bytes: classic CAN carries at most 8")]
    TooLong(usize),
}

/// A classic CAN data or remote frame (no CAN FD).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanFrame {
    id: CanId,
    data: [u8; 8],
    dlc: u8,
    remote: bool,
}

impl CanFrame {
    /// A data frame; fails when the id is out of range or `data` is longer
    /// than 8 bytes.
    pub fn new(id: CanId, data: &[u8]) -> Result<CanFrame, FrameError> {
        check_id(id)?;
        if data.len() > 8 {
            return Err(FrameError::TooLong(data.len()));
        }
        let mut buf = [0u8; 8];
        buf[..data.len()].copy_from_slice(data);
        Ok(CanFrame {
            id,
            data: buf,
            dlc: data.len() as u8,
            remote: false,
        })
    }

    /// A remote (request) frame asking for `dlc` bytes.
    pub fn remote(id: CanId, dlc: u8) -> Result<CanFrame, FrameError> {
        check_id(id)?;
        if dlc > 8 {
            return Err(FrameError::TooLong(usize::from(dlc)));
        }
        Ok(CanFrame {
            id,
            data: [0; 8],
            dlc,
            remote: true,
        })
    }

    /// The identifier.
    pub fn id(&self) -> CanId {
        self.id
    }

    /// The data bytes (empty for a remote frame).
    pub fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..usize::from(self.dlc)]
        }
    }

    /// Data length code (bytes carried, or requested by a remote frame).
    pub fn dlc(&self) -> u8 {
        self.dlc
    }

    /// True for a remote (request) frame.
    pub fn is_remote(&self) -> bool {
        self.remote
    }
}

fn check_id(id: CanId) -> Result<(), FrameError> {
    let ok = match id {
        CanId::Standard(v) => v <= 0x7FF,
        CanId::Extended(v) => v <= 0x1FFF_FFFF,
    };
    if ok {
        Ok(())
    } else {
        Err(FrameError::IdOutOfRange(id.raw()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_and_lengths_are_checked() {
        assert!(CanFrame::new(CanId::Standard(0x7FF), &[1, 2]).is_ok());
        assert_eq!(
            CanFrame::new(CanId::Standard(0x800), &[]),
            Err(FrameError::IdOutOfRange(0x800))
        );
        assert_eq!(
            CanFrame::new(CanId::Extended(0x2000_0000), &[]),
            Err(FrameError::IdOutOfRange(0x2000_0000))
        );
        assert_eq!(
            CanFrame::new(CanId::Standard(1), &[0; 9]),
            Err(FrameError::TooLong(9))
        );
        let r = CanFrame::remote(CanId::Extended(0x1234), 4).unwrap();
        assert!(r.is_remote() && r.data().is_empty() && r.dlc() == 4);
    }
}
