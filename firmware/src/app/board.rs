//! What the app needs from the hardware, or from an emulation of it.

use ocm_shared::protocol::SensorFrame;

/// What the app needs from the hardware (or from an emulation of it).
pub trait Board {
    /// The byte link to the host.
    type Link: embedded_io::Read + embedded_io::Write + embedded_io::ReadReady;
    /// The link.
    fn link(&mut self) -> &mut Self::Link;
    /// A free-running microsecond clock (wraps).
    fn now_us(&mut self) -> u32;
    /// A sample of the board's own sensors when one is due; boards whose
    /// sensors arrive over the link as [`ocm_shared::protocol::CommandBody::SensorFrame`] return
    /// `None`.
    fn sample(&mut self) -> Option<SensorFrame>;
    /// Drives the pressure regulators, Pa Q24.8, one per actuator.
    fn set_pressures(&mut self, pa_q8: &[i32]);
}
