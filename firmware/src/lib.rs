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
    use core::mem::MaybeUninit;
    use core::sync::atomic::{AtomicBool, Ordering};

    use catmodel::image::ImageError;
    use catmodel::node::drive::Drive;
    use catmodel::node::{Node, NodeConfig};

    /// The node as the firmware runs it: its drive stage in a static.
    pub type FirmwareNode = Node<&'static mut Drive>;

    include!(concat!(env!("OUT_DIR"), "/baked.rs"));

    /// The configuration of the car this firmware was built for.
    pub fn node_config() -> Result<NodeConfig, ImageError> {
        NodeConfig::from_image(&CONFIG_IMAGE)
    }

    /// The drive stage's state (about 35 KiB), built in place in uninitialised RAM
    /// ([`Drive::init`]): a value would pass through the 16 KiB stack, and a static initialised
    /// with `Drive::new()` keeps a 35 KiB copy of it in flash (`.data`). `None` after the first
    /// call.
    pub fn take_drive() -> Option<&'static mut Drive> {
        static TAKEN: AtomicBool = AtomicBool::new(false);
        // `.uninit`: neither in flash nor zeroed at reset (cortex-m-rt's section).
        #[link_section = ".uninit.catmodel.DRIVE"]
        static mut DRIVE: MaybeUninit<Drive> = MaybeUninit::uninit();
        if TAKEN.swap(true, Ordering::AcqRel) {
            return None;
        }
        // SAFETY: `TAKEN` lets exactly one caller through, so this is the only reference to
        // `DRIVE` there will ever be.
        let slot = unsafe { &mut *core::ptr::addr_of_mut!(DRIVE) };
        Some(Drive::init(slot))
    }

    /// Why the node could not be built.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum BootError {
        /// The configuration image is corrupt.
        Image(ImageError),
        /// The node was already built (its drive state is taken).
        AlreadyBuilt,
    }

    /// The node every platform runs. An error can only come from a corrupt image or a second
    /// call: the platforms stop rather than run a wrong model.
    pub fn node() -> Result<FirmwareNode, BootError> {
        let config = node_config().map_err(BootError::Image)?;
        let drive = take_drive().ok_or(BootError::AlreadyBuilt)?;
        Ok(Node::new(config, drive))
    }
}

#[cfg(all(target_os = "none", any(feature = "board", feature = "qemu")))]
pub mod platform;
