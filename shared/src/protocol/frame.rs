//! COBS framing with a CRC-16 trailer, streaming decoder and embedded-io
//! writer.

use crc::{CRC_16_IBM_3740, Crc};
use serde::{Serialize, de::DeserializeOwned};

/// Largest postcard payload (without CRC) a frame may carry.
pub const MAX_PAYLOAD: usize = 256;

/// Largest encoded frame on the wire, delimiter included.
pub const MAX_ENCODED_FRAME: usize = cobs::max_encoding_length(MAX_PAYLOAD + 2) + 1;

const FRAME_CRC: Crc<u16> = Crc::<u16>::new(&CRC_16_IBM_3740);

/// Why a frame could not be produced or understood.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum FrameError {
    /// More bytes arrived before a delimiter than any valid frame has.
    Oversized,
    /// The bytes between two delimiters are not valid COBS.
    Cobs,
    /// The frame is shorter than its CRC trailer.
    Truncated,
    /// The CRC trailer does not match the payload.
    Crc,
    /// The payload is not a valid postcard encoding of the expected message.
    Decode,
    /// The message does not fit into [`MAX_PAYLOAD`] bytes.
    Encode,
    /// The underlying byte stream failed.
    Io,
}

/// Encodes `msg` into `out` as one complete frame (delimiter included) and
/// returns the number of bytes written.
pub fn encode_frame<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_PAYLOAD + 2];
    let used = postcard::to_slice(msg, &mut raw[..MAX_PAYLOAD])
        .map_err(|_| FrameError::Encode)?
        .len();
    let crc = FRAME_CRC.checksum(&raw[..used]);
    raw[used..used + 2].copy_from_slice(&crc.to_le_bytes());
    let n = cobs::try_encode(&raw[..used + 2], out).map_err(|_| FrameError::Encode)?;
    let end = out.get_mut(n).ok_or(FrameError::Encode)?;
    *end = 0;
    Ok(n + 1)
}

/// Encodes `msg` and writes the whole frame to an embedded-io byte sink.
pub fn write_frame<T: Serialize, W: embedded_io::Write>(
    w: &mut W,
    msg: &T,
) -> Result<(), FrameError> {
    let mut buf = [0u8; MAX_ENCODED_FRAME];
    let n = encode_frame(msg, &mut buf)?;
    w.write_all(&buf[..n]).map_err(|_| FrameError::Io)?;
    w.flush().map_err(|_| FrameError::Io)
}

/// Checks the CRC of a COBS-decoded frame body and deserializes its payload.
pub fn decode_payload<T: DeserializeOwned>(body: &[u8]) -> Result<T, FrameError> {
    if body.len() < 2 {
        return Err(FrameError::Truncated);
    }
    let (payload, trailer) = body.split_at(body.len() - 2);
    let want = u16::from_le_bytes([trailer[0], trailer[1]]);
    if FRAME_CRC.checksum(payload) != want {
        return Err(FrameError::Crc);
    }
    let (msg, rest) = postcard::take_from_bytes::<T>(payload).map_err(|_| FrameError::Decode)?;
    if !rest.is_empty() {
        // Trailing bytes mean the sender and receiver disagree on the message
        // layout; accepting would silently ignore data.
        return Err(FrameError::Decode);
    }
    Ok(msg)
}

/// Streaming frame decoder: feed it bytes, get a message or an error at
/// each delimiter. Holds at most [`MAX_ENCODED_FRAME`] bytes.
#[derive(Debug, Clone)]
pub struct FrameDecoder {
    buf: [u8; MAX_ENCODED_FRAME],
    len: usize,
    overflow: bool,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameDecoder {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_ENCODED_FRAME],
            len: 0,
            overflow: false,
        }
    }

    /// Feeds one byte. Returns `None` until a delimiter ends a frame, then
    /// the decoded message or why the frame was rejected. Empty frames
    /// (two delimiters in a row) are ignored, so a host may send a lone
    /// `0x00` to resynchronise.
    pub fn push<T: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<T, FrameError>> {
        if byte != 0 {
            if self.len < self.buf.len() {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflow = true;
            }
            return None;
        }
        let len = core::mem::replace(&mut self.len, 0);
        if core::mem::replace(&mut self.overflow, false) {
            return Some(Err(FrameError::Oversized));
        }
        if len == 0 {
            return None;
        }
        let frame = &mut self.buf[..len];
        let n = match cobs::decode_in_place(frame) {
            Ok(n) => n,
            Err(_) => return Some(Err(FrameError::Cobs)),
        };
        Some(decode_payload(&frame[..n.min(len)]))
    }
}
