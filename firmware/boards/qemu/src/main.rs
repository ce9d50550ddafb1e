//! OCM firmware on QEMU mps2-an386: serves the protocol on UART0.
#![no_std]
#![no_main]

use core::ptr::addr_of_mut;

use cortex_m_rt::{entry, exception};
use ocm_board_qemu::{LUT_CAPACITY, QemuBoard, acknowledge_interrupts};
use ocm_firmware::app::{App, AppConfig};
use panic_halt as _;

static mut LUT_BUF: [u8; LUT_CAPACITY] = [0; LUT_CAPACITY];

#[entry]
fn main() -> ! {
    let Some(cp) = cortex_m::Peripherals::take() else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let mut board = QemuBoard::new(cp.SYST);
    // SAFETY: `main` runs once and is the only code touching LUT_BUF.
    let buf: &'static mut [u8] = unsafe { &mut *addr_of_mut!(LUT_BUF) };
    let mut app = App::new(buf, AppConfig::default());
    loop {
        app.poll(&mut board);
        board.idle();
    }
}

/// Every device interrupt only wakes the core.
#[exception]
unsafe fn DefaultHandler(_irqn: i16) {
    acknowledge_interrupts();
}
