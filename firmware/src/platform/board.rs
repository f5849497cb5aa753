//! The STM32F405RG board as a platform for the app layer (embassy-stm32).
//!
//! - Clocks: 8 MHz HSE crystal -> PLL (/4, x168, /2) -> SYSCLK 168 MHz; AHB 168 MHz, APB1
//!   42 MHz (bxCAN, TIM2 at 84 MHz), APB2 84 MHz; PLL Q /7 = 48 MHz.
//! - bxCAN1 at 500 kbit/s on PA11 (RX) / PA12 (TX), AF9: 42 MHz / 6 = 7 MHz time quanta,
//!   14 quanta per bit (1 sync + 11 + 2): exactly 500 000 bit/s, sample point 85.7 %, SJW 1.
//! - Hardware filters admit only the node's inputs ([`configure_filters`]), so the CPU never
//!   sees the rest of the bus.
//! - embassy-time on TIM2 (1 MHz ticks), IWDG at ~100 ms fed after each completed tick, DWT
//!   cycle counter for the step duration, reset cause from RCC CSR.
use core::num::{NonZeroU16, NonZeroU8};

use embassy_stm32::can::filter::{ListEntry16, Mask32};
use embassy_stm32::can::util::NominalBitTiming;
use embassy_stm32::can::{CanRx, CanTx, ExtendedId, Fifo, Frame, Id, StandardId};
use embassy_stm32::peripherals::IWDG;
use embassy_stm32::rcc::{
    AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv, PllSource,
    Sysclk,
};
use embassy_stm32::time::Hertz;
use embassy_stm32::wdg::IndependentWatchdog;

use crate::platform::stack::StackMeter;
use catmodel::can::spec::{
    MessageSpec, NODE_INPUT_STANDARD, PGN_COG_SOG_RAPID, PGN_POSITION_RAPID,
};
use catmodel::can::{CanFrame, CanId, TimedFrame};
use catmodel_app::health::{WatchdogFeeder, WatchdogTiming};
use catmodel_app::{BusReceiver, BusTransmitter, RxError, TickPlatform, TickReport};

/// Core clock, Hz (also the DWT cycle counter's rate): one definition, shared with the budgets.
pub use catmodel_app::budget::BOARD_SYSCLK_HZ as SYSCLK_HZ;
/// Watchdog timeout: five ticks at the nominal 32 kHz LSI; really 68..188 ms over the LSI's
/// tolerance ([`WATCHDOG`]). A hung or starved tick loop resets the node; a single tick may
/// stall up to 48 ms without a reset (counted as overruns).
pub const WATCHDOG_TIMEOUT_US: u32 = 100_000;
/// [`WATCHDOG_TIMEOUT_US`] with its LSI tolerance (tested on the host: `catmodel_app::health`).
pub const WATCHDOG: WatchdogTiming = WatchdogTiming {
    nominal_timeout_us: WATCHDOG_TIMEOUT_US,
};

/// Standard IDs the node listens to (steering, speed, pedal reports; the planner's PATH_HEADER,
/// PATH_POINT, PATH_LIMITS, OBSTACLE, LOCAL_ORIGIN; catmodel.dbc): the identifiers of
/// [`NODE_INPUT_STANDARD`], the software filter's list.
pub const INPUT_STANDARD_IDS: [u16; 8] = {
    let [a, b, c, d, e, f, g, h] = NODE_INPUT_STANDARD;
    [
        standard_id(a),
        standard_id(b),
        standard_id(c),
        standard_id(d),
        standard_id(e),
        standard_id(f),
        standard_id(g),
        standard_id(h),
    ]
};

/// A standard identifier's 11 bits (every message of [`NODE_INPUT_STANDARD`] has one).
const fn standard_id(spec: &MessageSpec) -> u16 {
    match spec.id {
        CanId::Standard(id) => id,
        CanId::Extended(_) => 0,
    }
}
/// NMEA 2000 PGNs the node listens to: 129025 position rapid update, 129026 COG & SOG rapid.
pub const INPUT_PGNS: [u32; 2] = [PGN_POSITION_RAPID, PGN_COG_SOG_RAPID];
/// The PGN field of a 29-bit NMEA 2000 / J1939 identifier: bits 8..25 (reserved, data page,
/// PDU format, PDU specific). Priority (26..28) and source address (0..7) are ignored.
pub const PGN_ID_MASK: u32 = 0x3FFFF << 8;

/// embassy-stm32 configuration: clocks as in the module doc.
pub fn config() -> embassy_stm32::Config {
    let mut config = embassy_stm32::Config::default();
    let rcc = &mut config.rcc;
    rcc.hse = Some(Hse {
        freq: Hertz(8_000_000),
        mode: HseMode::Oscillator,
    });
    rcc.pll_src = PllSource::HSE;
    rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL168,
        divp: Some(PllPDiv::DIV2),
        divq: Some(PllQDiv::DIV7),
        divr: None,
    });
    rcc.sys = Sysclk::PLL1_P;
    rcc.ahb_pre = AHBPrescaler::DIV1;
    rcc.apb1_pre = APBPrescaler::DIV4;
    rcc.apb2_pre = APBPrescaler::DIV2;
    config
}

/// 500 kbit/s from the 42 MHz APB1 clock: prescaler 6, 1 + 11 + 2 quanta.
pub fn bit_timing_500k() -> NominalBitTiming {
    const ONE: NonZeroU8 = NonZeroU8::MIN;
    NominalBitTiming {
        prescaler: NonZeroU16::new(6).unwrap_or(NonZeroU16::MIN),
        seg1: NonZeroU8::new(11).unwrap_or(ONE),
        seg2: NonZeroU8::new(2).unwrap_or(ONE),
        sync_jump_width: ONE,
    }
}

/// Whether the last reset was the independent watchdog's; clears the reset flags so that the
/// next reset is reported on its own.
pub fn take_watchdog_reset() -> bool {
    let rcc = embassy_stm32::pac::RCC;
    let watchdog = rcc.csr().read().wdgrstf();
    rcc.csr().modify(|w| w.set_rmvf(true));
    watchdog
}

fn standard_entry(raw: u16) -> ListEntry16 {
    // Note: the input IDs are constants below 0x800, so `new` cannot return None.
    ListEntry16::data_frames_with_id(StandardId::new(raw).unwrap_or(StandardId::MAX))
}

fn pgn_mask(pgn: u32) -> Mask32 {
    // Note: both values are below 2^29 by construction (PGN < 2^18, shifted by 8).
    let id = ExtendedId::new((pgn << 8) & PGN_ID_MASK).unwrap_or(ExtendedId::MAX);
    let mask = ExtendedId::new(PGN_ID_MASK).unwrap_or(ExtendedId::MAX);
    let mut filter = Mask32::frames_with_ext_id(id, mask);
    filter.data_frames_only();
    filter
}

/// Filter banks 0-3 of CAN1 (all into FIFO 0): two 16-bit lists of the eight standard IDs (a
/// list bank holds four), and one 32-bit mask per PGN (any priority, any source address).
/// Everything else is rejected in hardware.
pub fn configure_filters(can: &mut embassy_stm32::can::Can<'_>) {
    let [a, b, c, d, e, f, g, h] = INPUT_STANDARD_IDS.map(standard_entry);
    let [position, cog_sog] = INPUT_PGNS;
    can.modify_filters()
        .clear()
        .enable_bank(0, Fifo::Fifo0, [a, b, c, d])
        .enable_bank(1, Fifo::Fifo0, [e, f, g, h])
        .enable_bank(2, Fifo::Fifo0, pgn_mask(position))
        .enable_bank(3, Fifo::Fifo0, pgn_mask(cog_sog));
}

/// The node's frame from a bxCAN frame; `None` for remote frames.
fn from_bxcan(frame: &Frame) -> Option<CanFrame> {
    if frame.header().rtr() {
        return None;
    }
    let id = match frame.id() {
        Id::Standard(id) => CanId::Standard(id.as_raw()),
        Id::Extended(id) => CanId::Extended(id.as_raw()),
    };
    CanFrame::new(id, frame.data())
}

fn to_bxcan(frame: &CanFrame) -> Option<Frame> {
    match frame.id {
        CanId::Standard(id) => Frame::new_standard(id, frame.payload()).ok(),
        CanId::Extended(id) => Frame::new_extended(id, frame.payload()).ok(),
    }
}

/// Receive half of bxCAN1; frames are stamped with the receive interrupt's time (embassy
/// time, us since boot: the board's input time base).
pub struct BoardRx(pub CanRx<'static>);

impl BusReceiver for BoardRx {
    async fn receive(&mut self) -> Result<TimedFrame, RxError> {
        let envelope = self.0.read().await.map_err(|_| RxError::Bus)?;
        let frame = from_bxcan(&envelope.frame).ok_or(RxError::Unsupported)?;
        Ok(TimedFrame {
            t_us: envelope.ts.as_micros(),
            frame,
        })
    }
}

/// Transmit half of bxCAN1 (waits for a free mailbox).
pub struct BoardTx(pub CanTx<'static>);

impl BusTransmitter for BoardTx {
    async fn transmit(&mut self, frame: &TimedFrame) -> Result<(), ()> {
        let frame = to_bxcan(&frame.frame).ok_or(())?;
        let status = self.0.write(&frame).await;
        // With all three mailboxes busy, bxCAN swaps out a lower-priority pending frame: send it
        // again rather than lose it.
        if let Some(displaced) = status.dequeued_frame() {
            let displaced = *displaced;
            self.0.write(&displaced).await;
        }
        Ok(())
    }
}

/// The board's [`TickPlatform`]: DWT cycles, watchdog fed after each completed tick (and
/// nowhere else: [`WatchdogFeeder`]), stack high-water mark.
pub struct BoardTick {
    watchdog: IndependentWatchdog<'static, IWDG>,
    feeder: WatchdogFeeder,
    stack: StackMeter,
    logged_overruns: u32,
}

impl BoardTick {
    /// Starts the watchdog (it cannot be stopped again) and the cycle counter.
    pub fn start(
        mut watchdog: IndependentWatchdog<'static, IWDG>,
        dcb: &mut cortex_m::peripheral::DCB,
        dwt: &mut cortex_m::peripheral::DWT,
    ) -> Self {
        dcb.enable_trace();
        dwt.enable_cycle_counter();
        watchdog.unleash();
        Self {
            watchdog,
            feeder: WatchdogFeeder::new(),
            stack: StackMeter::new(),
            logged_overruns: 0,
        }
    }
}

impl TickPlatform for BoardTick {
    fn counter(&self) -> u32 {
        cortex_m::peripheral::DWT::cycle_count()
    }

    fn counts_to_us(&self, counts: u32) -> Option<u32> {
        Some(counts / (SYSCLK_HZ / 1_000_000))
    }

    fn tick_completed(&mut self, report: &TickReport) {
        if self.feeder.tick_completed(report.slot) {
            self.watchdog.pet();
        }
        if report.platform.overruns > self.logged_overruns {
            self.logged_overruns = report.platform.overruns;
            defmt::warn!(
                "tick overrun: {} deadline misses since boot (slot {})",
                report.platform.overruns,
                report.slot
            );
        }
    }

    fn stack_high_water_bytes(&mut self) -> Option<u32> {
        self.stack.step()
    }
}
