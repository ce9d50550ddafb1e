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
/// LUT upload buffer, the one capacity every board and host uses.
pub use ocm_shared::lut::LUT_CAPACITY;

const UART0: usize = 0x4000_4000;
const DATA: usize = 0x000;
const STATE: usize = 0x004;
const CTRL: usize = 0x008;
const BAUDDIV: usize = 0x010;
const INTCLEAR: usize = 0x00C;
const TX_FULL: u32 = 1 << 0;
const RX_FULL: u32 = 1 << 1;
/// CTRL: transmitter, receiver and receive interrupt enabled.
const CTRL_TX_RX_RXINT: u32 = 0b1011;
/// CMSDK APB timer 0: wakes the core every millisecond.
const TIMER0: usize = 0x4000_0000;
/// Interrupt numbers on mps2-an386: UART0 receive and timer 0.
const IRQ_UART0_RX: u32 = 0;
const IRQ_TIMER0: u32 = 8;
/// NVIC interrupt set-enable register 0.
const NVIC_ISER0: usize = 0xE000_E100;

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
            reg(CTRL).write_volatile(CTRL_TX_RX_RXINT);
        }
        Uart(())
    }

    /// Whether a received byte waits in the data register.
    pub fn rx_ready(&self) -> bool {
        self.state() & RX_FULL != 0
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
        let me = Self {
            uart: Uart::new(),
            clock: Cycles::new(syst),
        };
        enable_wakeups();
        me
    }
}

/// Acknowledges the wake-up interrupts (UART0 receive, timer 0); the main
/// loop does the work. Call from the interrupt handler.
pub fn acknowledge_interrupts() {
    // SAFETY: write-one-to-clear registers of UART0 and timer 0; clearing
    // an interrupt that is not pending has no effect.
    unsafe {
        reg(INTCLEAR).write_volatile(RX_FULL);
        ((TIMER0 + 0x00C) as *mut u32).write_volatile(1);
    }
}

/// Starts timer 0 at 1 kHz and enables the UART0 receive and timer 0
/// interrupts, so that [`QemuBoard::idle`] can sleep.
fn enable_wakeups() {
    // SAFETY: CMSDK timer 0 (CTRL, RELOAD, VALUE) and NVIC set-enable
    // registers of the mps2-an386 memory map; nothing else uses them.
    unsafe {
        let t = TIMER0 as *mut u32;
        t.add(2).write_volatile(CORE_HZ / 1_000);
        t.add(1).write_volatile(CORE_HZ / 1_000);
        // Enable, interrupt enable.
        t.write_volatile(0b1001);
        (NVIC_ISER0 as *mut u32).write_volatile((1 << IRQ_UART0_RX) | (1 << IRQ_TIMER0));
    }
}

impl QemuBoard {
    /// Sleeps until a byte arrives or the millisecond timer fires.
    ///
    /// Why: polling the UART state register in a tight loop makes every
    /// read a device access that QEMU serializes with its I/O thread, which
    /// then delivers received bytes slowly; a sleeping core leaves it free.
    /// Interrupts are masked around the check so a byte landing between the
    /// check and the WFI still wakes the core.
    pub fn idle(&mut self) {
        cortex_m::interrupt::free(|_| {
            if !self.uart.rx_ready() {
                cortex_m::asm::wfi();
            }
        });
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
