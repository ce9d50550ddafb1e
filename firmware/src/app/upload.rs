//! The LUT upload: an image arrives in chunks into the caller's buffer,
//! is checked (length, CRC-32, the image's own validation, the parameter
//! hash of the geometry) and then borrows that buffer for the rest of the
//! app's life, so one LUT can be loaded per boot; a second upload gets
//! [`ProtocolError::LutLocked`]. Failed uploads may be retried freely.

use crc::{CRC_32_ISO_HDLC, Crc};
use ocm_shared::lut::LutImage;
use ocm_shared::protocol::{ProtocolError, ReplyBody};

use super::{App, err};
use crate::maps::FastLut;

pub(super) const LUT_CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Where the LUT buffer stands.
pub(super) enum Lut<'a> {
    Empty(&'a mut [u8]),
    Uploading {
        buf: &'a mut [u8],
        total: u32,
        crc32: u32,
        received: u32,
    },
    Loaded(FastLut<'a>),
}

impl<'a> App<'a> {
    pub(super) fn lut_begin(&mut self, total: u32, crc32: u32) -> ReplyBody {
        if total > self.lut_capacity {
            return err(ProtocolError::LutTooLarge {
                capacity: self.lut_capacity,
            });
        }
        let lut = core::mem::replace(&mut self.lut, Lut::Empty(Default::default()));
        let (next, reply) = match lut {
            Lut::Loaded(img) => (Lut::Loaded(img), err(ProtocolError::LutLocked)),
            Lut::Empty(buf) | Lut::Uploading { buf, .. } => (
                Lut::Uploading {
                    buf,
                    total,
                    crc32,
                    received: 0,
                },
                ReplyBody::LutProgress { received: 0 },
            ),
        };
        self.lut = next;
        reply
    }

    pub(super) fn lut_chunk(&mut self, offset: u32, data: &[u8]) -> ReplyBody {
        match &mut self.lut {
            Lut::Uploading {
                buf,
                total,
                received,
                ..
            } => {
                if offset != *received {
                    return err(ProtocolError::LutOutOfOrder {
                        expected: *received,
                        got: offset,
                    });
                }
                let end = (offset as usize).saturating_add(data.len());
                if end > *total as usize {
                    return err(ProtocolError::LutTooLarge {
                        capacity: self.lut_capacity,
                    });
                }
                let Some(dst) = buf.get_mut(offset as usize..end) else {
                    return err(ProtocolError::LutTooLarge {
                        capacity: self.lut_capacity,
                    });
                };
                dst.copy_from_slice(data);
                *received = end as u32;
                ReplyBody::LutProgress {
                    received: *received,
                }
            }
            Lut::Loaded(_) => err(ProtocolError::LutLocked),
            Lut::Empty(_) => err(ProtocolError::LutNotStarted),
        }
    }

    #[inline(never)]
    pub(super) fn lut_commit(&mut self) -> ReplyBody {
        let want_hash = self.geometry.ocm.hash();
        // Validate through a shared reborrow first, so a failure leaves the
        // upload exactly as it was.
        match &self.lut {
            Lut::Uploading {
                buf,
                total,
                crc32,
                received,
            } => {
                if received != total {
                    return err(ProtocolError::LutIncomplete {
                        received: *received,
                        total: *total,
                    });
                }
                let bytes = buf.get(..*total as usize).unwrap_or(&[]);
                if LUT_CRC.checksum(bytes) != *crc32 {
                    return err(ProtocolError::LutCrc);
                }
                match LutImage::parse(bytes) {
                    Ok(img) if img.param_hash() != want_hash => {
                        return err(ProtocolError::LutParamMismatch);
                    }
                    Ok(_) => {}
                    Err(_) => return err(ProtocolError::LutInvalid),
                }
            }
            Lut::Loaded(_) => return err(ProtocolError::LutLocked),
            Lut::Empty(_) => return err(ProtocolError::LutNotStarted),
        }
        let lut = core::mem::replace(&mut self.lut, Lut::Empty(Default::default()));
        let Lut::Uploading { buf, total, .. } = lut else {
            self.lut = lut;
            return err(ProtocolError::LutNotStarted);
        };
        let frozen: &'a [u8] = buf;
        let bytes = frozen.get(..total as usize).unwrap_or(&[]);
        match LutImage::parse(bytes) {
            Ok(img) => {
                self.lut = Lut::Loaded(FastLut::new(img));
                self.refresh_bend_pressures();
                ReplyBody::LutLoaded {
                    param_hash: img.param_hash(),
                    len: total,
                }
            }
            // Unreachable after the check above; keep the app consistent
            // (and panic-free) anyway: the buffer is lost, not the app.
            Err(_) => err(ProtocolError::LutInvalid),
        }
    }
}
