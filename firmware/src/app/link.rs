//! The byte link: frames in, one reply out per frame, and the main loop
//! that serves a [`Board`].

use embedded_io::ReadReady;
use ocm_shared::protocol::{Command, ProtocolError, Reply, ReplyBody, write_frame};

use super::{App, Board, err};

impl<'a> App<'a> {
    /// Feeds received bytes through the frame decoder; for every complete
    /// frame, handles it and writes the reply with `send`.
    pub fn receive_bytes(&mut self, bytes: &[u8], now_us: u32, mut send: impl FnMut(&Reply)) {
        for &b in bytes {
            match self.decoder.push::<Command>(b) {
                None => {}
                Some(Ok(cmd)) => {
                    let reply = self.handle(&cmd, now_us);
                    send(&reply);
                }
                Some(Err(e)) => send(&Reply {
                    seq: 0,
                    body: err(ProtocolError::Frame(e)),
                }),
            }
        }
    }

    /// One pass of the main loop: watchdog, link input, board-sampled
    /// tick, outputs. Never blocks on the link's input.
    pub fn poll<B: Board>(&mut self, board: &mut B) {
        let now = board.now_us();
        self.service(now);
        let mut buf = [0u8; 64];
        loop {
            let ready = board.link().read_ready().unwrap_or(false);
            if !ready {
                break;
            }
            let n = match embedded_io::Read::read(board.link(), &mut buf) {
                Ok(n) if n > 0 => n,
                _ => break,
            };
            for &b in &buf[..n] {
                let reply = match self.decoder.push::<Command>(b) {
                    None => continue,
                    Some(Ok(cmd)) => {
                        let t0 = board.now_us();
                        let mut r = self.handle(&cmd, t0);
                        if let ReplyBody::Telemetry(t) = &mut r.body {
                            t.loop_time_us = board.now_us().wrapping_sub(t0);
                        }
                        r
                    }
                    Some(Err(e)) => Reply {
                        seq: 0,
                        body: err(ProtocolError::Frame(e)),
                    },
                };
                let _ = write_frame(board.link(), &reply);
            }
            let out = self.commanded();
            board.set_pressures(&out[..self.actuators()]);
        }
        if let Some(frame) = board.sample() {
            let t0 = board.now_us();
            let body = self.control_tick(&frame);
            let t1 = board.now_us();
            self.sampled_ticks = self.sampled_ticks.wrapping_add(1);
            let every = self.config.telemetry_every;
            if every > 0 && self.sampled_ticks.is_multiple_of(every) {
                let mut reply = Reply { seq: 0, body };
                if let ReplyBody::Telemetry(t) = &mut reply.body {
                    t.loop_time_us = t1.wrapping_sub(t0);
                }
                let _ = write_frame(board.link(), &reply);
            }
        }
        let out = self.commanded();
        board.set_pressures(&out[..self.actuators()]);
    }
}
