//! CDR payloads as ROS 2 puts them on the wire and rosbag2 stores them in MCAP: a 4-byte
//! encapsulation header (`00 01 00 00` for little-endian plain CDR) followed by the
//! serialised message, aligned relative to the end of the header.

use anyhow::{bail, Result};
use byteorder::{BigEndian, LittleEndian};
use serde::de::DeserializeOwned;
use serde::Serialize;

/// Encapsulation header of little-endian plain CDR.
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Serialises a message as a little-endian CDR payload with its encapsulation header.
pub fn encode<M: Serialize>(msg: &M) -> Vec<u8> {
    let mut buf = Vec::with_capacity(128);
    buf.extend_from_slice(&CDR_LE);
    cdr_encoding::to_writer::<M, LittleEndian, _>(&mut buf, msg).expect("CDR serialisation into memory cannot fail");
    buf
}

/// Appends the payload of `msg` to `buf` (cleared first); avoids an allocation per message.
pub fn encode_into<M: Serialize>(msg: &M, buf: &mut Vec<u8>) {
    buf.clear();
    buf.extend_from_slice(&CDR_LE);
    cdr_encoding::to_writer::<M, LittleEndian, _>(&mut *buf, msg).expect("CDR serialisation into memory cannot fail");
}

/// Deserialises a CDR payload (little- or big-endian plain CDR).
pub fn decode<M: DeserializeOwned>(payload: &[u8]) -> Result<M> {
    if payload.len() < 4 {
        bail!("CDR payload of {} bytes is shorter than its 4-byte header", payload.len());
    }
    let body = &payload[4..];
    let r = match payload[1] {
        0x01 => cdr_encoding::from_bytes::<M, LittleEndian>(body),
        0x00 => cdr_encoding::from_bytes::<M, BigEndian>(body),
        k => bail!("unsupported CDR encapsulation kind 0x{:02x}{k:02x} (expected plain CDR)", payload[0]),
    };
    match r {
        Ok((m, _)) => Ok(m),
        Err(e) => bail!("CDR payload does not decode: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{Abscissa, AbscissaBatch};
    use crate::std_msgs::msg::Header;

    #[test]
    fn layout_is_ros2_cdr() {
        let m = Abscissa {
            header: Header::at(1_500_000_000_250_000_000, "d"),
            station: 2,
            beam: 7,
            abscissa_m: 0.5,
            signal_strength: 1.0,
            beam_broken: true,
            trigger_id: 9,
        };
        let b = encode(&m);
        // header: sec (4) nanosec (4) frame_id: len 2 ("d\0") (4+2), pad to 4 -> 16 bytes;
        // station, beam (8) -> 24; pad to 8 -> 24; abscissa, signal (16) -> 40; bool (1) -> 41;
        // pad to 8 -> 48; trigger_id (8) -> 56. Plus the 4-byte encapsulation header.
        assert_eq!(b.len(), 4 + 56);
        assert_eq!(&b[..4], &CDR_LE);
        assert_eq!(&b[4..8], &1_500_000_000i32.to_le_bytes());
        assert_eq!(&b[12..16], &2u32.to_le_bytes());
        assert_eq!(&b[16..18], b"d\0");
        assert_eq!(&b[28..36], &0.5f64.to_le_bytes());
        assert_eq!(b[44], 1);
        assert_eq!(&b[52..60], &9u64.to_le_bytes());
        assert_eq!(decode::<Abscissa>(&b).unwrap(), m);
    }

    #[test]
    fn sequences_round_trip_and_garbage_is_an_error() {
        let m = AbscissaBatch {
            sample_period_s: 1e-4,
            abscissa_m: vec![0.1, 0.2, 0.3],
            signal_strength: vec![1.0, 0.5, 0.25],
            beam_broken: vec![false, true, false],
            ..Default::default()
        };
        assert_eq!(decode::<AbscissaBatch>(&encode(&m)).unwrap(), m);
        assert!(decode::<AbscissaBatch>(&[0, 1, 0]).is_err());
        assert!(decode::<AbscissaBatch>(&[0, 1, 0, 0, 5, 0, 0, 0]).is_err());
    }
}
