//! The firmware over a byte link (issue modes b and c): COBS-framed
//! postcard messages on a serial port, exactly as a real board speaks them.
//! [`SerialLink::open`] takes any serial device, a board's `/dev/ttyACM0`
//! or the pty QEMU gives its UART ([`crate::qemu`]).

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

use ocm_shared::protocol::{
    Command, CommandBody, FrameDecoder, MAX_ENCODED_FRAME, Reply, ReplyBody, encode_frame,
};

use crate::SimError;
use crate::firmware::Link;

/// How long a read spins for bytes before it blocks (one core busy while
/// a run waits on the firmware).
const SPIN: Duration = Duration::from_millis(10);

/// A firmware instance behind a serial device.
pub struct SerialLink {
    path: String,
    port: Box<dyn serialport::SerialPort>,
    decoder: FrameDecoder,
    /// Bytes read but not yet decoded (a read may end inside a frame or
    /// hold the start of the next).
    pending: VecDeque<u8>,
    timeout: Duration,
}

impl SerialLink {
    /// Opens `path` at `baud` and waits (up to `wait`) for the firmware to
    /// answer a ping: bytes sent before the other end listens are lost, so
    /// it pings until a pong comes back, then drains late pongs.
    pub fn open(path: &str, baud: u32, wait: Duration) -> Result<Self, SimError> {
        let port = serialport::new(path, baud)
            .timeout(Duration::from_millis(20))
            .open()
            .map_err(|e| SimError::Io {
                path: path.to_string(),
                message: format!("cannot open the serial port: {e}"),
            })?;
        let mut link = Self {
            path: path.to_string(),
            port,
            decoder: FrameDecoder::new(),
            pending: VecDeque::new(),
            timeout: Duration::from_secs(5),
        };
        let nonce = 0x0c3e;
        let end = Instant::now() + wait;
        let mut seq = 0xff00u16;
        loop {
            seq = seq.wrapping_add(1);
            link.send(&Command {
                seq,
                body: CommandBody::Ping { nonce },
            })?;
            if let Some(r) = link.recv(Duration::from_millis(200))?
                && r.body == (ReplyBody::Pong { nonce })
            {
                break;
            }
            if Instant::now() > end {
                return Err(SimError::Io {
                    path: path.to_string(),
                    message: format!("no firmware answered a ping within {wait:?}"),
                });
            }
        }
        while link.recv(Duration::from_millis(100))?.is_some() {}
        Ok(link)
    }

    /// The device path.
    pub fn path(&self) -> &str {
        &self.path
    }

    fn io(&self, message: String) -> SimError {
        SimError::Io {
            path: self.path.clone(),
            message,
        }
    }

    fn send(&mut self, cmd: &Command) -> Result<(), SimError> {
        let mut buf = [0u8; MAX_ENCODED_FRAME];
        let n = encode_frame(cmd, &mut buf).map_err(|e| self.io(format!("encoding: {e:?}")))?;
        // No flush: on a tty it is tcdrain(), which waits for the far end
        // to take the bytes and costs a millisecond per frame on a pty.
        self.port
            .write_all(&buf[..n])
            .map_err(|e| self.io(format!("write: {e}")))
    }

    /// The next complete reply frame, or `None` after `timeout`.
    fn recv(&mut self, timeout: Duration) -> Result<Option<Reply>, SimError> {
        let end = Instant::now() + timeout;
        let mut buf = [0u8; 256];
        loop {
            while let Some(b) = self.pending.pop_front() {
                if let Some(r) = self.decoder.push::<Reply>(b) {
                    return r
                        .map(Some)
                        .map_err(|e| self.io(format!("malformed reply frame: {e:?}")));
                }
            }
            if Instant::now() >= end {
                return Ok(None);
            }
            // Spin before blocking: a reply is usually under way, and waking
            // a blocked thread (in a VM, an idle CPU) costs more than the
            // bytes take to come; under QEMU a SensorFrame exchange takes
            // 0.8 ms spinning against 1.3-2 ms blocking.
            let spin_end = Instant::now() + SPIN;
            while self.port.bytes_to_read().unwrap_or(1) == 0 && Instant::now() < spin_end {
                std::hint::spin_loop();
            }
            let n = match self.port.read(&mut buf) {
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => 0,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => 0,
                Err(e) => return Err(self.io(format!("read: {e}"))),
            };
            self.pending.extend(&buf[..n]);
        }
    }
}

impl SerialLink {
    fn reply_to(&mut self, cmd: &Command) -> Result<Reply, SimError> {
        let end = Instant::now() + self.timeout;
        loop {
            let left = end.saturating_duration_since(Instant::now());
            match self.recv(left)? {
                // Late pongs or telemetry of an earlier session: skip.
                Some(r) if r.seq != cmd.seq => continue,
                Some(r) => return Ok(r),
                None => {
                    return Err(self.io(format!(
                        "no reply to command {} within {:?}",
                        cmd.seq, self.timeout
                    )));
                }
            }
        }
    }
}

impl Link for SerialLink {
    fn exchange(&mut self, cmd: &Command, _now_us: u32) -> Result<Reply, SimError> {
        self.send(cmd)?;
        self.reply_to(cmd)
    }

    fn exchange_all(
        &mut self,
        cmds: &[Command],
        _now_us: u32,
        replies: &mut Vec<Reply>,
    ) -> Result<(), SimError> {
        for c in cmds {
            self.send(c)?;
        }
        for c in cmds {
            replies.push(self.reply_to(c)?);
        }
        Ok(())
    }
}
