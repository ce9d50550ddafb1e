//! OCM firmware on an STM32F411 ("Black Pill") board.
//!
//! Wiring (see firmware/README.md):
//! * USART1 (PA9 TX, PA10 RX), 115 200 baud: the host link.
//! * I2C1 (PB8 SCL, PB9 SDA), 400 kHz: ADS1115 at 0x48 (ADDR to GND), Hall
//!   sensors of the three columns on A0..A2, +-4.096 V range, 860 SPS.
//! * ADC1 on PA0, PA1, PA4: analog chamber pressure sensors (0.5..4.5 V over
//!   -50..+50 kPa through a 2:3 divider, e.g. an NXP MPXV7050-type part).
//! * TIM3 PWM on PA6, PA7, PB0 at 20 kHz: RC-filtered set-points of the
//!   three pressure regulators, duty 0..100 % = -20..35 kPa by default.
//!
//! The board samples its own sensors every control period (three one-shot
//! ADS1115 conversions bound the rate to 250 Hz) and runs the same `App` as
//! QEMU and the simulator; telemetry goes out every 25 ticks.
#![no_std]
#![no_main]

use core::ptr::addr_of_mut;

use ads1x1x::{Ads1x1x, DataRate16Bit, FullScaleRange, TargetAddr, channel, ic, mode};
use cortex_m::peripheral::DWT;
use cortex_m_rt::entry;
use ocm_firmware::app::{App, AppConfig, Board};
use ocm_shared::lut::LUT_CAPACITY;
use ocm_shared::protocol::SensorFrame;
use panic_halt as _;
use stm32f4xx_hal::adc::Adc;
use stm32f4xx_hal::adc::config::{AdcConfig, SampleTime};
use stm32f4xx_hal::gpio::{Analog, Pin};
use stm32f4xx_hal::i2c::I2c;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::serial::Serial;
use stm32f4xx_hal::timer::PwmChannel;

const SYSCLK_HZ: u32 = 100_000_000;
const CONTROL_PERIOD_US: u32 = 4_000;
/// Pressure that maps to 0 % and 100 % PWM duty, Pa Q24.8.
const REG_MIN_Q8: i64 = -20_000 * 256;
const REG_MAX_Q8: i64 = 35_000 * 256;

static mut LUT_BUF: [u8; LUT_CAPACITY] = [0; LUT_CAPACITY];

/// USART1 as an embedded-io byte stream with a one-byte look-ahead, so that
/// `read_ready` never loses a byte.
struct Link {
    serial: Serial<pac::USART1>,
    peek: Option<u8>,
}

impl embedded_io::ErrorType for Link {
    type Error = core::convert::Infallible;
}

impl Link {
    fn poll_byte(&mut self) -> Option<u8> {
        if let Some(b) = self.peek.take() {
            return Some(b);
        }
        // Framing/overrun errors drop the byte; the frame CRC catches it.
        embedded_hal_nb::serial::Read::read(&mut self.serial).ok()
    }
}

impl embedded_io::ReadReady for Link {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        if self.peek.is_none() {
            self.peek = embedded_hal_nb::serial::Read::read(&mut self.serial).ok();
        }
        Ok(self.peek.is_some())
    }
}

impl embedded_io::Read for Link {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let Some(first) = buf.first_mut() else {
            return Ok(0);
        };
        *first = loop {
            if let Some(b) = self.poll_byte() {
                break b;
            }
        };
        let mut n = 1;
        while n < buf.len() {
            match self.poll_byte() {
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

impl embedded_io::Write for Link {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        // A failed write loses the frame; the host sees no reply and retries.
        let _ = embedded_io::Write::write_all(&mut self.serial, buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        let _ = embedded_io::Write::flush(&mut self.serial);
        Ok(())
    }
}

type Hall = Ads1x1x<I2c<pac::I2C1>, ic::Ads1115, ic::Resolution16Bit, mode::OneShot>;

struct Stm32Board {
    link: Link,
    hall: Hall,
    adc: Adc<pac::ADC1>,
    p_pins: (
        Pin<'A', 0, Analog>,
        Pin<'A', 1, Analog>,
        Pin<'A', 4, Analog>,
    ),
    pwm: (
        PwmChannel<pac::TIM3, 0>,
        PwmChannel<pac::TIM3, 1>,
        PwmChannel<pac::TIM3, 2>,
    ),
    last_cycles: u32,
    micros: u64,
    residue: u32,
    next_sample_us: u32,
}

impl Stm32Board {
    /// Pressure in Pa from a 12-bit ADC code (divider 2:3, 0.5..4.5 V over
    /// -50..+50 kPa, 3.3 V reference).
    fn pressure_pa(code: u16) -> i32 {
        let sensor_mv = i64::from(code) * 3_300 * 3 / (2 * 4_095);
        ((sensor_mv - 2_500) * 100_000 / 4_000) as i32
    }
}

impl Board for Stm32Board {
    type Link = Link;

    fn link(&mut self) -> &mut Link {
        &mut self.link
    }

    fn now_us(&mut self) -> u32 {
        // DWT cycles (wrap every 43 s at 100 MHz) extended in software.
        let now = DWT::cycle_count();
        let cycles = now.wrapping_sub(self.last_cycles) + self.residue;
        self.last_cycles = now;
        let per_us = SYSCLK_HZ / 1_000_000;
        self.micros += u64::from(cycles / per_us);
        self.residue = cycles % per_us;
        self.micros as u32
    }

    fn sample(&mut self) -> Option<SensorFrame> {
        let now = self.now_us();
        if (now.wrapping_sub(self.next_sample_us) as i32) < 0 {
            return None;
        }
        self.next_sample_us = self.next_sample_us.wrapping_add(CONTROL_PERIOD_US);
        // A failed conversion reports a saturated code, which the safety
        // layer flags as an implausible Hall reading.
        let a0 = nb::block!(self.hall.read(channel::SingleA0)).unwrap_or(i16::MAX);
        let a1 = nb::block!(self.hall.read(channel::SingleA1)).unwrap_or(i16::MAX);
        let a2 = nb::block!(self.hall.read(channel::SingleA2)).unwrap_or(i16::MAX);
        let (p0, p1, p2) = (&self.p_pins.0, &self.p_pins.1, &self.p_pins.2);
        let p = [
            Self::pressure_pa(self.adc.convert(p0, SampleTime::Cycles_112)),
            Self::pressure_pa(self.adc.convert(p1, SampleTime::Cycles_112)),
            Self::pressure_pa(self.adc.convert(p2, SampleTime::Cycles_112)),
        ];
        Some(SensorFrame {
            hall_codes: heapless::Vec::from_slice(&[a0, a1, a2]).unwrap_or_default(),
            // No IMU on this board: identity, with the IMU weight set to 0.
            imu_quat_q14: [16_384, 0, 0, 0],
            pressures_pa: heapless::Vec::from_slice(&p).unwrap_or_default(),
        })
    }

    fn set_pressures(&mut self, pa_q8: &[i32]) {
        let max = i64::from(self.pwm.0.get_max_duty());
        let duty = |p: Option<&i32>| {
            let p = i64::from(p.copied().unwrap_or(0));
            ((p - REG_MIN_Q8).clamp(0, REG_MAX_Q8 - REG_MIN_Q8) * max / (REG_MAX_Q8 - REG_MIN_Q8))
                as u16
        };
        self.pwm.0.set_duty(duty(pa_q8.first()));
        self.pwm.1.set_duty(duty(pa_q8.get(1)));
        self.pwm.2.set_duty(duty(pa_q8.get(2)));
    }
}

#[entry]
fn main() -> ! {
    let (Some(dp), Some(mut cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let rcc = dp.RCC.constrain();
    let clocks = rcc.cfgr.use_hse(25.MHz()).sysclk(SYSCLK_HZ.Hz()).freeze();
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();

    let gpioa = dp.GPIOA.split();
    let gpiob = dp.GPIOB.split();

    let Ok(serial) = dp
        .USART1
        .serial((gpioa.pa9, gpioa.pa10), 115_200.bps(), &clocks)
    else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let i2c = I2c::new(
        dp.I2C1,
        (gpiob.pb8, gpiob.pb9),
        stm32f4xx_hal::i2c::Mode::standard(100.kHz()),
        &clocks,
    );
    let mut hall = Ads1x1x::new_ads1115(i2c, TargetAddr::Gnd);
    let _ = hall.set_full_scale_range(FullScaleRange::Within4_096V);
    let _ = hall.set_data_rate(DataRate16Bit::Sps860);
    let adc = Adc::adc1(dp.ADC1, true, AdcConfig::default());
    let p_pins = (
        gpioa.pa0.into_analog(),
        gpioa.pa1.into_analog(),
        gpioa.pa4.into_analog(),
    );
    let (_, (c1, c2, c3, ..)) = dp.TIM3.pwm_hz(20.kHz(), &clocks);
    let mut pwm = (c1.with(gpioa.pa6), c2.with(gpioa.pa7), c3.with(gpiob.pb0));
    pwm.0.enable();
    pwm.1.enable();
    pwm.2.enable();

    let mut board = Stm32Board {
        link: Link { serial, peek: None },
        hall,
        adc,
        p_pins,
        pwm,
        last_cycles: DWT::cycle_count(),
        micros: 0,
        residue: 0,
        next_sample_us: 0,
    };
    // SAFETY: `main` runs once and is the only code touching LUT_BUF.
    let buf: &'static mut [u8] = unsafe { &mut *addr_of_mut!(LUT_BUF) };
    let config = AppConfig {
        control_period_us: CONTROL_PERIOD_US,
        telemetry_every: 25,
        imu_weight_q15: 0,
    };
    let mut app = App::new(buf, config);
    loop {
        app.poll(&mut board);
    }
}
