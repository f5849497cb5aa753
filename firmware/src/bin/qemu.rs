//! catmodel on QEMU `-M netduinoplus2` (STM32F405): the same app layer and node as the board,
//! over a replayed candump drive, with per-tick instruction counts. Run it with `cargo qemu`
//! (docs/firmware.md); QEMU's exit status is this program's.
#![no_std]
#![no_main]

use catmodel_app::{self as app, LinkCounters, RxQueue, TxQueue};
use catmodel_firmware::platform::qemu::{executor, icount, replay, run, time_driver};
use cortex_m_rt::entry;
// The `defmt` feature is on for the core's types; nothing here logs through it, but a global
// logger must exist for any dependency that does.
use defmt_semihosting as _;

static RX_QUEUE: RxQueue = RxQueue::new();
static TX_QUEUE: TxQueue = TxQueue::new();
static COUNTERS: LinkCounters = LinkCounters::new();

// The replay harness's buffers (input line reader, tx log, tick records: about 6 KiB) live in
// statics and the tasks get references: passed by value they would be copied through main's
// stack frame and again through the executor's spawn, tripling the stack the harness needs
// (measured: 19 KiB high-water mark before, see docs/firmware.md "Stack").

#[embassy_executor::task]
async fn receive_task(bus: &'static mut replay::ReplayBus) {
    app::receive_loop(bus, &RX_QUEUE, &COUNTERS).await;
}

#[embassy_executor::task]
async fn transmit_task(bus: &'static mut replay::TxLog) {
    app::transmit_loop(bus, &TX_QUEUE, &COUNTERS).await
}

#[embassy_executor::task]
async fn tick_task(
    recorder: &'static mut run::TickRecorder,
    config: app::TickConfig,
    input: replay::InputSummary,
) {
    let boot_start = icount::now();
    let node = catmodel_firmware::baked::node();
    let node_boot_instructions = icount::now().wrapping_sub(boot_start);
    let Ok(mut node) = node else {
        // The published model failed to build: nothing correct can be sent.
        semihosting::process::exit(3)
    };
    let summary = app::tick_loop(
        &mut node, &RX_QUEUE, &TX_QUEUE, &COUNTERS, recorder, &config,
    )
    .await;
    app::wait_tx_drained(&COUNTERS).await;
    let trailer = catmodel_app::record::Trailer {
        node_boot_instructions,
        ..run::trailer(&summary, &COUNTERS, &input)
    };
    if !recorder.finish(&trailer) {
        run::fail("cannot write the tick records", 1);
    }
    semihosting::eprintln!(
        "catmodel-qemu: {} ticks, {} frames in, {} overruns, {} rx queue drops",
        summary.ticks,
        input.frames,
        summary.overruns,
        trailer.rx_queue_drops
    );
    if trailer.tx_bus_errors > 0 {
        run::fail("cannot write the tx log", 1);
    }
    semihosting::process::exit(0)
}

/// What the tasks get: references to the harness statics, and two small values.
struct Harness {
    bus: &'static mut replay::ReplayBus,
    tx_log: &'static mut replay::TxLog,
    recorder: &'static mut run::TickRecorder,
    config: app::TickConfig,
    input: replay::InputSummary,
}

/// Reads the command line, opens the files, builds the harness statics. Not inlined: its
/// frame (options, paths, the values on their way into the statics) is gone before the
/// executor runs, instead of staying under every tick's stack.
#[inline(never)]
fn set_up() -> Harness {
    let options = run::options().unwrap_or_else(|message| run::fail(message, 2));
    if options.stack_overflow_test {
        semihosting::eprintln!(
            "catmodel-qemu: stack overflow test: recursing until the stack guard faults"
        );
        core::hint::black_box(run::overflow_stack(0));
        run::fail("the stack overflowed without a fault", 3);
    }
    let (reader, input) = run::open_input(&options);
    let config = run::tick_config(&input);
    let tx_log =
        cortex_m::singleton!(: replay::TxLog = replay::TxLog::new(run::create(&options.tx_log)))
            .unwrap_or_else(|| run::fail("harness statics taken twice", 3));
    let recorder = cortex_m::singleton!(: run::TickRecorder =
        run::TickRecorder::new(run::create(&options.ticks), options.stalls.clone()))
    .unwrap_or_else(|| run::fail("harness statics taken twice", 3));
    let bus = cortex_m::singleton!(: replay::ReplayBus =
        replay::ReplayBus::new(reader, catmodel_app::ReplayClock::new(input.first_t_us)))
    .unwrap_or_else(|| run::fail("harness statics taken twice", 3));
    Harness {
        bus,
        tx_log,
        recorder,
        config,
        input,
    }
}

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        run::fail("core peripherals taken twice", 3)
    };
    icount::init();
    let harness = set_up();
    // Last: set-up time must not count as elapsed virtual time.
    time_driver::start(core.SYST);
    executor::run(|spawner| {
        let Harness {
            bus,
            tx_log,
            recorder,
            config,
            input,
        } = harness;
        spawner.spawn(receive_task(bus).unwrap_or_else(|_| run::fail("spawn", 3)));
        spawner.spawn(transmit_task(tx_log).unwrap_or_else(|_| run::fail("spawn", 3)));
        spawner.spawn(tick_task(recorder, config, input).unwrap_or_else(|_| run::fail("spawn", 3)));
    })
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    semihosting::eprintln!("catmodel-qemu: panic: {info}");
    semihosting::process::exit(101)
}
