//! Classic CAN 2.0 frames as the node sees them.

/// A CAN identifier: 11-bit standard (our own messages) or 29-bit extended (NMEA 2000 GNSS).
///
/// `repr(u32)`: a 4-byte tag before the value, so that a frame is five aligned words and
/// moves as such (with the default layout's 2-byte tag the compiler copied a frame's other 18
/// bytes with a library `memcpy`, about 100 instructions per frame on the Cortex-M4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u32)]
pub enum CanId {
    /// 11-bit identifier, 0..=0x7FF.
    Standard(u16),
    /// 29-bit identifier, 0..=0x1FFF_FFFF.
    Extended(u32),
}

impl CanId {
    /// The raw identifier value (11 or 29 bits).
    pub const fn raw(self) -> u32 {
        match self {
            CanId::Standard(id) => id as u32,
            CanId::Extended(id) => id,
        }
    }

    /// Whether the value fits the identifier's width.
    pub const fn is_valid(self) -> bool {
        match self {
            CanId::Standard(id) => id <= 0x7FF,
            CanId::Extended(id) => id <= 0x1FFF_FFFF,
        }
    }
}

/// One classic CAN data frame: identifier, data length code 0..=8 and up to 8 data bytes.
/// Bytes past `len` are zero.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CanFrame {
    /// Identifier.
    pub id: CanId,
    /// Data length code, 0..=8.
    pub len: u8,
    /// Payload; only the first `len` bytes are meaningful, the rest are zero.
    pub data: [u8; 8],
}

impl CanFrame {
    /// The empty standard frame 0 (a slot to encode into).
    pub const EMPTY: CanFrame = CanFrame {
        id: CanId::Standard(0),
        len: 0,
        data: [0; 8],
    };

    /// A frame with `data` as payload; `None` if `data` is longer than 8 bytes or the id is out
    /// of range.
    pub fn new(id: CanId, data: &[u8]) -> Option<Self> {
        if data.len() > 8 || !id.is_valid() {
            return None;
        }
        let mut bytes = [0u8; 8];
        bytes.get_mut(..data.len())?.copy_from_slice(data);
        Some(Self {
            id,
            len: data.len() as u8,
            data: bytes,
        })
    }

    /// The meaningful bytes.
    pub fn payload(&self) -> &[u8] {
        self.data.get(..usize::from(self.len.min(8))).unwrap_or(&[])
    }
}

/// A frame with the time it was received, in microseconds on the input's time base.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimedFrame {
    /// Receive time, us.
    pub t_us: u64,
    /// The frame.
    pub frame: CanFrame,
}
