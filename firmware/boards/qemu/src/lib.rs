//! The QEMU `mps2-an386` board: CMSDK UART0 as the host link, SysTick as
//! the clock, no local sensors (they arrive as `SensorFrame`s) and no
//! pressure outputs (the commanded pressures travel back in telemetry).
#![no_std]

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use ocm_firmware::app::Board;
use ocm_shared::protocol::SensorFrame;

/// Core clock of the AN386 image, Hz.
pub const CORE_HZ: u32 = 25_000_000;
/// LUT upload buffer: the default LUT image (25 984 bytes) plus slack,
/// sized so that the whole firmware fits the 32 KiB RAM budget.
pub const LUT_CAPACITY: usize = 26 * 1024;

const UART0: usize = 0x4000_4000;
const DATA: usize = 0x000;
const STATE: usize = 0x004;
const CTRL: usize = 0x008;
const BAUDDIV: usize = 0x010;
const TX_FULL: u32 = 1 << 0;
const RX_FULL: u32 = 1 << 1;

fn reg(offset: usize) -> *mut u32 {
    (UART0 + offset) as *mut u32
}

/// CMSDK APB UART0.
pub struct Uart(());

impl Uart {
    /// Enables TX and RX (the baud divisor only matters on hardware).
    pub fn new() -> Self {
        // SAFETY: fixed MMIO addresses of UART0 on this machine; this is the
        // only owner (constructed once in `QemuBoard::new`).
        unsafe {
            reg(BAUDDIV).write_volatile(16);
            reg(CTRL).write_volatile(0b11);
        }
        Uart(())
    }

    fn state(&self) -> u32 {
        // SAFETY: read of a status register, no side effects.
        unsafe { reg(STATE).read_volatile() }
    }

    /// Writes one byte, waiting while the TX buffer is full.
    pub fn write_byte(&mut self, b: u8) {
        while self.state() & TX_FULL != 0 {}
        // SAFETY: TX buffer has room; writing DATA queues the byte.
        unsafe { reg(DATA).write_volatile(u32::from(b)) }
    }

    /// One received byte if any.
    pub fn read_byte(&mut self) -> Option<u8> {
        if self.state() & RX_FULL == 0 {
            return None;
        }
        // SAFETY: RX buffer holds a byte; reading DATA pops it.
        Some(unsafe { reg(DATA).read_volatile() } as u8)
    }
}

impl Default for Uart {
    fn default() -> Self {
        Self::new()
    }
}

impl embedded_io::ErrorType for Uart {
    type Error = core::convert::Infallible;
}

impl embedded_io::Read for Uart {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        // Block for the first byte (embedded-io semantics), then take what
        // is already there.
        let first = loop {
            if let Some(b) = self.read_byte() {
                break b;
            }
        };
        buf[0] = first;
        let mut n = 1;
        while n < buf.len() {
            match self.read_byte() {
                Some(b) => {
                    buf[n] = b;
                    n += 1;
                }
                None => break,
            }
        }
        Ok(n)
    }
}

impl embedded_io::ReadReady for Uart {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.state() & RX_FULL != 0)
    }
}

impl embedded_io::Write for Uart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        for &b in buf {
            self.write_byte(b);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// A 64-bit cycle counter built on the 24-bit SysTick; call often enough
/// (at least every 0.67 s at 25 MHz).
pub struct Cycles {
    syst: SYST,
    last: u32,
    total: u64,
}

impl Cycles {
    /// Starts SysTick on the core clock, free running.
    pub fn new(mut syst: SYST) -> Self {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(0x00FF_FFFF);
        syst.clear_current();
        syst.enable_counter();
        Self {
            syst,
            last: SYST::get_current(),
            total: 0,
        }
    }

    /// Core cycles since start.
    pub fn now(&mut self) -> u64 {
        let cur = SYST::get_current();
        // SysTick counts down.
        self.total += u64::from(self.last.wrapping_sub(cur) & 0x00FF_FFFF);
        self.last = cur;
        let _ = &self.syst;
        self.total
    }
}

/// The board.
pub struct QemuBoard {
    uart: Uart,
    clock: Cycles,
}

impl QemuBoard {
    /// Takes the UART and SysTick.
    pub fn new(syst: SYST) -> Self {
        Self {
            uart: Uart::new(),
            clock: Cycles::new(syst),
        }
    }
}

impl Board for QemuBoard {
    type Link = Uart;

    fn link(&mut self) -> &mut Uart {
        &mut self.uart
    }

    fn now_us(&mut self) -> u32 {
        (self.clock.now() / u64::from(CORE_HZ / 1_000_000)) as u32
    }

    fn sample(&mut self) -> Option<SensorFrame> {
        None
    }

    fn set_pressures(&mut self, _pa_q8: &[i32]) {}
}
