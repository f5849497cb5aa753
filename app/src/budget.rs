//! The firmware's budgets, written down next to the code that must meet them and imported by
//! `cargo xtask` (which measures them) instead of copied there.
use catmodel::SAMPLE_PERIOD_US;

/// The board's core clock, Hz: the STM32F405's maximum, from the 8 MHz crystal through the PLL
/// (docs/firmware.md).
pub const BOARD_SYSCLK_HZ: u32 = 168_000_000;
/// Cycles in one 20 ms tick at [`BOARD_SYSCLK_HZ`]: the basis of every "share of the tick".
pub const CYCLES_PER_TICK: u64 = BOARD_SYSCLK_HZ as u64 / 1_000_000 * SAMPLE_PERIOD_US;
/// Instructions one tick may take (drain + step + handoff) while the node estimates and
/// predicts, for any input: no controller plans and no planner frame arrives in it (those are
/// controller ticks, `TickEstimate::controller_tick`). 25 000 = 0.74 % of a 20 ms tick at
/// 168 MHz if every instruction took one cycle. `cargo qemu` checks that the tick's worst-case
/// bound (docs/firmware.md, "Worst-case tick") is within it and that every measured tick is
/// within the bound, on QEMU instruction counts.
pub const TICK_BUDGET_INSTRUCTIONS: u32 = 25_000;
/// Instructions one tick may take when a controller plans in it (the model-predictive
/// controller's solve included): 600 000 = 18 % of the tick at 168 MHz, one cycle each. The
/// controller's worst-case bound is checked against it the same way.
pub const CONTROL_TICK_BUDGET_INSTRUCTIONS: u32 = 600_000;
/// Flash the board image may use, bytes (the STM32F405RG has 1 MiB; the budget leaves room for
/// a second image).
pub const FLASH_BUDGET_BYTES: u64 = 192 * 1024;
/// RAM the board image may use with its stack region, bytes (of the 128 KiB SRAM1+2).
pub const RAM_BUDGET_BYTES: u64 = 64 * 1024;
/// Share of the stack region the measured high-water mark may use (the rest is headroom for
/// the board's interrupt handlers and code paths the drive does not take).
pub const STACK_USE_LIMIT: f64 = 0.75;
