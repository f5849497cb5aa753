//! The thin platform glue under the app layer ([`catmodel_app`]): one module per target.
//! Only built for the embedded target with exactly one of the `board` / `qemu` features.
#[cfg(all(feature = "board", feature = "qemu"))]
compile_error!("features `board` and `qemu` are exclusive: each brings its own time driver");

#[cfg(feature = "board")]
pub mod board;
#[cfg(feature = "qemu")]
pub mod qemu;
pub mod stack;
