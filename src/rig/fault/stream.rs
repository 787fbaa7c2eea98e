//! The protocol faults of a served streaming DAQ: a device that sends its
//! records on a serial line unasked, so there is no request to leave
//! unanswered and no exception to reply with. Each record's bytes are
//! passed through [`ProtocolFaults::stream_record`] before they go out:
//! while a `bus_timeout` lasts the DAQ falls silent (its records are
//! dropped, as a DAQ whose buffer overflowed drops them); while `garbage`
//! lasts each record comes after a few bytes of noise; while a
//! `crc_error` lasts each record's check (the ASCII line's checksum, the
//! binary frame's CRC) is wrong; once a `disconnect` has happened the DAQ
//! hangs up its end of the line. The simulated CAN encoder's frames take
//! the silence and the hang-up alone ([`ProtocolFaults::withheld`]).

use motorbench_drivers::serial::SerialFraming;

use super::line::GARBAGE;
use super::ProtocolFaults;
use crate::config::FaultKind;

/// What a streaming DAQ does with one record now.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StreamRecordFate {
    /// Send these bytes.
    Send(Vec<u8>),
    /// Send nothing (the DAQ is silent).
    Drop,
    /// Close the line for good.
    HangUp,
}

impl ProtocolFaults {
    /// What becomes of `frame`, one record as `framing` encodes it, under
    /// the faults acting now.
    pub fn stream_record(&self, framing: SerialFraming, mut frame: Vec<u8>) -> StreamRecordFate {
        if let Some(fate) = self.withheld() {
            return fate;
        }
        if self.acting(FaultKind::CrcError).is_some() {
            corrupt_check(framing, &mut frame);
        }
        if self.acting(FaultKind::Garbage).is_some() {
            frame.splice(0..0, GARBAGE);
        }
        StreamRecordFate::Send(frame)
    }

    /// Whether a streaming device withholds its next record or frame now:
    /// [`StreamRecordFate::HangUp`] once a `disconnect` has happened,
    /// [`StreamRecordFate::Drop`] while a `bus_timeout` lasts, else `None`
    /// (it sends). The simulated CAN encoder's frames take only this: a
    /// CAN controller retransmits a frame whose CRC fails by itself, and
    /// garbage on an adapter's line is [`super::FaultyLine`]'s.
    pub fn withheld(&self) -> Option<StreamRecordFate> {
        if self.acting(FaultKind::Disconnect).is_some() {
            Some(StreamRecordFate::HangUp)
        } else if self.acting(FaultKind::BusTimeout).is_some() {
            Some(StreamRecordFate::Drop)
        } else {
            None
        }
    }
}

/// Flip the lowest bit of the record's check: the last checksum digit of
/// an ASCII line (`…*HH\r\n`), the last CRC byte of a binary frame (before
/// its `0x00` delimiter; should that byte become `0x00`, the frame ends
/// early, which its CRC refuses as well).
fn corrupt_check(framing: SerialFraming, frame: &mut [u8]) {
    let from_end = match framing {
        SerialFraming::Ascii => 3,
        SerialFraming::Binary => 2,
    };
    if let Some(k) = frame.len().checked_sub(from_end) {
        frame[k] ^= 0x01;
    }
}

#[cfg(test)]
mod tests {
    use motorbench_drivers::serial::{ascii, binary, DecodeCounts, StreamRecord};

    use super::*;

    fn record() -> StreamRecord {
        StreamRecord {
            seq: 7,
            t_us: 1_250_000,
            values: vec![
                ("armature_voltage".into(), 60.02),
                ("armature_current".into(), 0.5),
            ],
        }
    }

    /// The records a decoder of `framing` takes from `bytes`, and its
    /// counts.
    fn decode(framing: SerialFraming, bytes: &[u8]) -> (usize, DecodeCounts) {
        let mut out = Vec::new();
        match framing {
            SerialFraming::Ascii => {
                let mut d = ascii::AsciiDecoder::default();
                d.feed(bytes, &mut out);
                (out.len(), d.counts())
            }
            SerialFraming::Binary => {
                let mut d = binary::BinaryDecoder::default();
                // A receiver syncs on the first delimiter.
                d.feed(&[0], &mut out);
                d.feed(bytes, &mut out);
                (out.len(), d.counts())
            }
        }
    }

    #[test]
    fn a_corrupted_check_is_refused_and_garbage_skipped_in_both_framings() {
        for framing in [SerialFraming::Ascii, SerialFraming::Binary] {
            let frame = match framing {
                SerialFraming::Ascii => ascii::encode(&record()),
                SerialFraming::Binary => binary::encode(&record()),
            };
            let (good, _) = decode(framing, &frame);
            assert_eq!(good, 1, "{framing:?}: the clean record decodes");

            let StreamRecordFate::Send(bad) =
                ProtocolFaults::one(FaultKind::CrcError).stream_record(framing, frame.clone())
            else {
                panic!("{framing:?}: a record with a bad check is still sent");
            };
            let (n, counts) = decode(framing, &[bad, frame.clone()].concat());
            assert_eq!(n, 1, "{framing:?}: only the clean record after it decodes");
            assert!(counts.rejected >= 1, "{framing:?}: {counts:?}");

            let StreamRecordFate::Send(noisy) =
                ProtocolFaults::one(FaultKind::Garbage).stream_record(framing, frame.clone())
            else {
                panic!("{framing:?}: a record after garbage is still sent");
            };
            assert_eq!(&noisy[..GARBAGE.len()], &GARBAGE);
            // The noise may take the record it precedes with it (a binary
            // frame then starts with noise); the decoder recovers after.
            let (n, counts) = decode(framing, &[frame.clone(), noisy, frame.clone()].concat());
            assert!(n >= 2, "{framing:?}: {n} records decoded around the noise");
            assert!(
                counts.skipped_bytes + counts.rejected > 0,
                "{framing:?}: the noise is counted: {counts:?}"
            );
        }
    }

    #[test]
    fn a_silent_daq_drops_its_records_and_a_disconnected_one_hangs_up() {
        let frame = ascii::encode(&record());
        assert_eq!(
            ProtocolFaults::one(FaultKind::BusTimeout)
                .stream_record(SerialFraming::Ascii, frame.clone()),
            StreamRecordFate::Drop
        );
        assert_eq!(
            ProtocolFaults::one(FaultKind::Disconnect).stream_record(SerialFraming::Ascii, frame),
            StreamRecordFate::HangUp
        );
    }
}
