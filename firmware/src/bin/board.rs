//! catmodel on an STM32F405RG: bxCAN1 at 500 kbit/s in, `Node::step` every 20 ms, bxCAN1 out.
//! Build: `cargo build --profile firmware -p catmodel-firmware --features board --bin
//! catmodel-board --target thumbv7em-none-eabihf`; flash and watch the defmt log: `cargo run
//! ...` (probe-rs runner).
#![no_std]
#![no_main]

use catmodel::SAMPLE_PERIOD_US;
use catmodel_app::{self as app, LinkCounters, RxQueue, TickConfig, TxQueue};
use catmodel_firmware::platform::board::{self, BoardRx, BoardTick, BoardTx};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::bind_interrupts;
use embassy_stm32::can::{self, Can};
use embassy_stm32::peripherals::CAN1;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::Instant;

bind_interrupts!(struct Irqs {
    CAN1_TX => can::TxInterruptHandler<CAN1>;
    CAN1_RX0 => can::Rx0InterruptHandler<CAN1>;
    CAN1_RX1 => can::Rx1InterruptHandler<CAN1>;
    CAN1_SCE => can::SceInterruptHandler<CAN1>;
});

/// A panic outside the core (the core has no panic path, `cargo xtask no-panic`; embassy-stm32's
/// init and the board's set-up have): its location over defmt, then a permanently undefined
/// instruction, whose fault halts the core until the watchdog resets it, as panic-probe does.
/// Without the message: formatting it linked 0.8 KiB more of `core::fmt` (`cargo xtask size`).
#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    use core::sync::atomic::{AtomicBool, Ordering};
    static PANICKED: AtomicBool = AtomicBool::new(false);
    cortex_m::interrupt::disable();
    // A panic while logging the first one goes straight to the fault.
    if !PANICKED.swap(true, Ordering::Relaxed) {
        match info.location() {
            Some(at) => defmt::error!("panicked at {=str}:{=u32}", at.file(), at.line()),
            None => defmt::error!("panicked"),
        }
    }
    cortex_m::asm::udf()
}

static RX_QUEUE: RxQueue = RxQueue::new();
static TX_QUEUE: TxQueue = TxQueue::new();
static COUNTERS: LinkCounters = LinkCounters::new();

#[embassy_executor::task]
async fn receive_task(mut bus: BoardRx) {
    app::receive_loop(&mut bus, &RX_QUEUE, &COUNTERS).await;
}

#[embassy_executor::task]
async fn transmit_task(mut bus: BoardTx) {
    app::transmit_loop(&mut bus, &TX_QUEUE, &COUNTERS).await
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let watchdog_reset = board::take_watchdog_reset();
    let p = embassy_stm32::init(board::config());
    let mut core =
        cortex_m::Peripherals::take().unwrap_or_else(|| defmt::panic!("core peripherals"));
    defmt::info!("catmodel board up; watchdog reset: {}", watchdog_reset);

    // PA11 = CAN1_RX, PA12 = CAN1_TX (AF9). The alternative pins are PB8 / PB9.
    let mut can = Can::new(p.CAN1, p.PA11, p.PA12, Irqs);
    board::configure_filters(&mut can);
    can.modify_config()
        .set_bit_timing(board::bit_timing_500k())
        .set_automatic_retransmit(true);
    can.enable().await;
    let (tx, rx) = can.split();
    spawner.spawn(receive_task(BoardRx(rx)).unwrap_or_else(|_| defmt::panic!("spawn")));
    spawner.spawn(transmit_task(BoardTx(tx)).unwrap_or_else(|_| defmt::panic!("spawn")));

    let watchdog = IndependentWatchdog::new(p.IWDG, board::WATCHDOG_TIMEOUT_US);
    let mut platform = BoardTick::start(watchdog, &mut core.DCB, &mut core.DWT);
    // The board's time base is its own clock: ticks on whole multiples of 20 ms since boot.
    let first_tick_us = (Instant::now().as_micros() / SAMPLE_PERIOD_US + 2) * SAMPLE_PERIOD_US;
    let config = TickConfig {
        first_tick_instant_us: first_tick_us,
        input_offset_us: 0,
        last_tick_us: None,
        watchdog_reset,
    };
    let Ok(mut node) = catmodel_firmware::baked::node() else {
        // The published model failed to build: nothing correct can be sent. Stay silent on
        // the bus; the planner sees the node missing.
        defmt::error!("model configuration invalid");
        loop {
            cortex_m::asm::wfi();
        }
    };
    app::tick_loop(
        &mut node,
        &RX_QUEUE,
        &TX_QUEUE,
        &COUNTERS,
        &mut platform,
        &config,
    )
    .await;
    // Note: tick_loop returns only at `last_tick_us`, which the board never sets. Should it ever
    // return, park: `can` must stay alive (dropping it resets the peripheral) and the watchdog,
    // no longer fed, resets the node.
    core::future::pending::<()>().await;
}
