//! The tick-record format: what the QEMU firmware writes, one record per tick, and `cargo qemu`
//! (xtask) reads back for `timing.json`. One definition, used by both ends.
//!
//! Layout, little-endian: a 12-byte header (`b"CMQT"`, [`FORMAT_VERSION`], [`RECORD_LEN`]),
//! then one [`TickRecord`] of [`RECORD_LEN`] bytes per tick, then the [`Trailer`]
//! (`b"END!"` and its fields, [`TRAILER_LEN`] bytes). A file without the trailer means the
//! firmware did not finish.

/// Header magic.
pub const MAGIC: [u8; 4] = *b"CMQT";
/// Trailer magic.
pub const TRAILER_MAGIC: [u8; 4] = *b"END!";
/// Layout version (4: each record ends with its flags).
pub const FORMAT_VERSION: u32 = 4;
/// Bytes of the header.
pub const HEADER_LEN: usize = 12;
/// Bytes of one tick record.
pub const RECORD_LEN: usize = 44;
/// Bytes of the trailer, magic included.
pub const TRAILER_LEN: usize = 4 + 8 + 12 * 4;

/// One tick as the QEMU firmware measured it (counts are TIM2 ticks = instructions).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TickRecord {
    /// The tick's time on the input's time base, us.
    pub tick_us: u64,
    /// Slot on the 20 ms grid.
    pub slot: u64,
    /// Overruns so far.
    pub overruns: u32,
    /// Receive-queue drops so far.
    pub rx_queue_drops: u32,
    /// Frames handed to the node.
    pub rx_frames: u16,
    /// Frames the node returned.
    pub tx_frames: u16,
    /// Instructions moving due frames out of the queue.
    pub drain: u32,
    /// Instructions in `Node::step`.
    pub step: u32,
    /// Instructions for the whole tick.
    pub tick: u32,
    /// [`FLAG_CONTROLLER`] and future per-tick facts.
    pub flags: u32,
}

/// [`TickRecord::flags`]: a controller planned in this tick, or a planner path was completed
/// in it (`TickEstimate::controller_tick`).
pub const FLAG_CONTROLLER: u32 = 1;

impl TickRecord {
    /// A controller planned in this tick.
    pub fn controller(&self) -> bool {
        self.flags & FLAG_CONTROLLER != 0
    }
}

/// Totals written after the last tick record.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Trailer {
    /// Ticks that ran.
    pub ticks: u64,
    /// Deadline misses.
    pub overruns: u32,
    /// Skipped slots.
    pub skipped_slots: u32,
    /// Receive-queue drops.
    pub rx_queue_drops: u32,
    /// Receive bus errors.
    pub rx_bus_errors: u32,
    /// Frames the node cannot use.
    pub rx_unsupported: u32,
    /// Transmit-queue drops.
    pub tx_queue_drops: u32,
    /// Transmit failures (host file writes).
    pub tx_bus_errors: u32,
    /// Frames in the input.
    pub input_frames: u32,
    /// Remote / CAN FD frames in the input (skipped).
    pub input_unsupported: u32,
    /// Deepest stack use of the run, bytes (painted-stack scan at the end).
    pub stack_high_water: u32,
    /// The stack region's size, bytes.
    pub stack_size: u32,
    /// Instructions to build the node at boot (reading the configuration image).
    pub node_boot_instructions: u32,
}

/// Why a record file could not be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordError {
    /// Not a tick-record file.
    BadHeader,
    /// Another layout version.
    Version(u32),
    /// No trailer: the firmware did not finish.
    Truncated,
}

/// `fields` one after the other; bytes past `N` are dropped, missing ones are zero.
fn pack<const N: usize>(fields: &[&[u8]]) -> [u8; N] {
    let mut out = [0u8; N];
    let mut at = 0;
    for field in fields {
        if let Some(dst) = out.get_mut(at..at + field.len()) {
            dst.copy_from_slice(field);
        }
        at += field.len();
    }
    out
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    let mut w = [0u8; 2];
    if let Some(src) = b.get(at..at + 2) {
        w.copy_from_slice(src);
    }
    u16::from_le_bytes(w)
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut w = [0u8; 4];
    if let Some(src) = b.get(at..at + 4) {
        w.copy_from_slice(src);
    }
    u32::from_le_bytes(w)
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut w = [0u8; 8];
    if let Some(src) = b.get(at..at + 8) {
        w.copy_from_slice(src);
    }
    u64::from_le_bytes(w)
}

/// The file header.
pub fn header() -> [u8; HEADER_LEN] {
    pack(&[
        &MAGIC,
        &FORMAT_VERSION.to_le_bytes(),
        &(RECORD_LEN as u32).to_le_bytes(),
    ])
}

impl TickRecord {
    /// The record's bytes.
    pub fn encode(&self) -> [u8; RECORD_LEN] {
        pack(&[
            &self.tick_us.to_le_bytes(),
            &self.slot.to_le_bytes(),
            &self.overruns.to_le_bytes(),
            &self.rx_queue_drops.to_le_bytes(),
            &self.rx_frames.to_le_bytes(),
            &self.tx_frames.to_le_bytes(),
            &self.drain.to_le_bytes(),
            &self.step.to_le_bytes(),
            &self.tick.to_le_bytes(),
            &self.flags.to_le_bytes(),
        ])
    }

    /// A record from its bytes (missing bytes read as zero).
    pub fn decode(r: &[u8]) -> Self {
        Self {
            tick_us: u64_at(r, 0),
            slot: u64_at(r, 8),
            overruns: u32_at(r, 16),
            rx_queue_drops: u32_at(r, 20),
            rx_frames: u16_at(r, 24),
            tx_frames: u16_at(r, 26),
            drain: u32_at(r, 28),
            step: u32_at(r, 32),
            tick: u32_at(r, 36),
            flags: u32_at(r, 40),
        }
    }
}

impl Trailer {
    /// The trailer's bytes, magic included.
    pub fn encode(&self) -> [u8; TRAILER_LEN] {
        pack(&[
            &TRAILER_MAGIC,
            &self.ticks.to_le_bytes(),
            &self.overruns.to_le_bytes(),
            &self.skipped_slots.to_le_bytes(),
            &self.rx_queue_drops.to_le_bytes(),
            &self.rx_bus_errors.to_le_bytes(),
            &self.rx_unsupported.to_le_bytes(),
            &self.tx_queue_drops.to_le_bytes(),
            &self.tx_bus_errors.to_le_bytes(),
            &self.input_frames.to_le_bytes(),
            &self.input_unsupported.to_le_bytes(),
            &self.stack_high_water.to_le_bytes(),
            &self.stack_size.to_le_bytes(),
            &self.node_boot_instructions.to_le_bytes(),
        ])
    }

    fn decode(t: &[u8]) -> Self {
        Self {
            ticks: u64_at(t, 0),
            overruns: u32_at(t, 8),
            skipped_slots: u32_at(t, 12),
            rx_queue_drops: u32_at(t, 16),
            rx_bus_errors: u32_at(t, 20),
            rx_unsupported: u32_at(t, 24),
            tx_queue_drops: u32_at(t, 28),
            tx_bus_errors: u32_at(t, 32),
            input_frames: u32_at(t, 36),
            input_unsupported: u32_at(t, 40),
            stack_high_water: u32_at(t, 44),
            stack_size: u32_at(t, 48),
            node_boot_instructions: u32_at(t, 52),
        }
    }
}

/// Splits a record file into its tick records and its trailer.
pub fn parse(
    bytes: &[u8],
) -> Result<(impl Iterator<Item = TickRecord> + '_, Trailer), RecordError> {
    let (Some(magic), Some(body)) = (bytes.get(..4), bytes.get(HEADER_LEN..)) else {
        return Err(RecordError::BadHeader);
    };
    if magic != MAGIC || u32_at(bytes, 8) as usize != RECORD_LEN {
        return Err(RecordError::BadHeader);
    }
    let version = u32_at(bytes, 4);
    if version != FORMAT_VERSION {
        return Err(RecordError::Version(version));
    }
    let Some(records_len) = body.len().checked_sub(TRAILER_LEN) else {
        return Err(RecordError::Truncated);
    };
    if !records_len.is_multiple_of(RECORD_LEN) {
        return Err(RecordError::Truncated);
    }
    let (records, trailer) = body.split_at(records_len);
    if trailer.get(..4) != Some(&TRAILER_MAGIC[..]) {
        return Err(RecordError::Truncated);
    }
    let trailer = Trailer::decode(trailer.get(4..).unwrap_or(&[]));
    Ok((
        records.chunks_exact(RECORD_LEN).map(TickRecord::decode),
        trailer,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_and_trailer_round_trip() {
        let record = TickRecord {
            tick_us: 1_700_000_000_020_000,
            slot: 7,
            overruns: 1,
            rx_queue_drops: 2,
            rx_frames: 5,
            tx_frames: 14,
            drain: 2_000,
            step: 18_000,
            tick: 21_000,
            flags: FLAG_CONTROLLER,
        };
        let trailer = Trailer {
            ticks: 8,
            stack_high_water: 7_900,
            stack_size: 12_288,
            ..Trailer::default()
        };
        let mut file = header().to_vec();
        file.extend_from_slice(&record.encode());
        file.extend_from_slice(&record.encode());
        file.extend_from_slice(&trailer.encode());
        let (records, back) = parse(&file).unwrap();
        assert_eq!(records.collect::<Vec<_>>(), vec![record, record]);
        assert_eq!(back, trailer);
        assert_eq!(
            parse(&file[..file.len() - 1]).err(),
            Some(RecordError::Truncated)
        );
        assert_eq!(parse(b"CMQ").err(), Some(RecordError::BadHeader));
    }
}
