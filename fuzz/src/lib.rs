//! Shared pieces of the fuzz targets: arbitrary CAN frames.
use arbitrary::Arbitrary;
use catmodel::can::{CanFrame, CanId};

/// Any frame a bus could carry, including invalid DLCs (the controller reports 0..=15).
#[derive(Arbitrary, Debug, Clone, Copy)]
pub struct RawFrame {
    /// 29-bit identifier (masked), else 11-bit.
    pub extended: bool,
    /// Identifier bits (masked to the width).
    pub id: u32,
    /// Data length code, 0..=15.
    pub len: u8,
    /// Payload bytes.
    pub data: [u8; 8],
}

impl RawFrame {
    /// The frame, with the identifier masked to its width and the DLC to 4 bits.
    pub fn frame(&self) -> CanFrame {
        let id = if self.extended {
            CanId::Extended(self.id & 0x1FFF_FFFF)
        } else {
            CanId::Standard((self.id & 0x7FF) as u16)
        };
        CanFrame {
            id,
            len: self.len & 0x0F,
            data: self.data,
        }
    }
}
