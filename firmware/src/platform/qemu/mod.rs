//! QEMU `-M netduinoplus2` (an STM32F405) as a platform for the app layer.
//!
//! QEMU 7.2 emulates the Cortex-M4F core (SysTick, NVIC, FPU), TIM2-5 and the USARTs of this
//! machine, but RCC, GPIO and bxCAN are placeholders that read 0, so embassy-stm32 cannot run
//! here. This module is the small glue that replaces it:
//! - [`time_driver`]: embassy-time on SysTick (1 kHz interrupt, 1 us resolution),
//! - [`executor`]: a raw embassy executor that sleeps with WFI (QEMU treats WFE as a no-op),
//! - [`icount`]: TIM2 counting one per executed instruction under `-icount shift=0`,
//! - [`replay`]: the "bus": a candump file (semihosting) or the bundled drive, frames released
//!   to the tick whose time has come, and the transmit side writing candump lines,
//! - [`run`]: command line, records of every tick for `cargo qemu`, exit codes,
//! - [`stages`]: the tick's stages measured one by one (the worst-case bound's maxima).
pub mod candump;
pub mod executor;
pub mod icount;
pub mod replay;
pub mod run;
pub mod stages;
pub mod time_driver;
