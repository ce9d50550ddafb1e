//! Wire protocol between a host (PC, simulator, sensor board) and the OCM
//! firmware.
//!
//! A frame on the byte stream is `COBS(postcard(message) ++ crc16_le) ++ 0x00`.
//! The CRC (CRC-16/IBM-3740, also called CCITT-FALSE) covers the postcard
//! bytes, so a corrupted frame is rejected before it is interpreted.
//! The host sends [`Command`]s, the firmware answers each with one
//! [`Reply`] that echoes the command's sequence number.
//!
//! Fixed-point and integer units on the wire are the firmware's own (see
//! the suffixes): lengths in metres Q8.24, angles in radians Q3.28,
//! pressures in pascals Q24.8, quaternions Q2.14, Hall codes as the ADC's
//! `i16`. Values a human types
//! (gains, limits, loads) travel as `f32` in SI units and are range-checked
//! by the firmware.

mod frame;
mod messages;

pub use frame::{
    FrameDecoder, FrameError, MAX_ENCODED_FRAME, MAX_PAYLOAD, decode_payload, encode_frame,
    write_frame,
};
pub use messages::*;

/// Protocol revision; bumped on any incompatible change of the messages.
pub const PROTOCOL_VERSION: u16 = 1;
