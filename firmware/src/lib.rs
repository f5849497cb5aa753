//! catmodel on the STM32F405: thin platforms around the app layer (`catmodel-app`) and the core
//! (`catmodel`), and the car this build runs.
//!
//! - [`baked`]: the car's configuration image, made by the build script from the model file
//!   (`models/paper.toml`, or the file named by `CATMODEL_MODEL`) with the host's own reader
//!   (`catmodel-model-file`): discretized and designed in f64 there, baked as f32 words here,
//!   checked word by word when the node starts ([`catmodel::node::NodeConfig::from_image`]).
//! - `platform` (embedded target only): the board (embassy-stm32: clocks, bxCAN1, IWDG, DWT)
//!   and QEMU netduinoplus2 (SysTick time driver, replay bus over semihosting, TIM2 instruction
//!   counts) glue; `src/bin/` the binaries.
#![no_std]
#![deny(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]
#![warn(missing_docs)]

pub mod baked {
    //! The model file baked in at build time (see the build script).
    use catmodel::image::ImageError;
    use catmodel::node::{Node, NodeConfig};

    include!(concat!(env!("OUT_DIR"), "/baked.rs"));

    /// The configuration of the car this firmware was built for.
    pub fn node_config() -> Result<NodeConfig, ImageError> {
        NodeConfig::from_image(&CONFIG_IMAGE)
    }

    /// The node every platform runs. An error can only come from a corrupt image: the
    /// platforms stop rather than run a wrong model.
    pub fn node() -> Result<Node, ImageError> {
        node_config().map(Node::new)
    }
}

#[cfg(all(target_os = "none", any(feature = "board", feature = "qemu")))]
pub mod platform;
