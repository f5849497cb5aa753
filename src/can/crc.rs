//! CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xorout 0xFF, no reflection), the integrity check of
//! every frame the node sends and of the drive-by-wire reports it receives (Dataspeed ds_dbw
//! convention). Check value: `crc8_sae_j1850(b"123456789") == 0x4B`.
use super::frame::CanId;

/// Generator polynomial x^8 + x^4 + x^3 + x^2 + 1 (0x1D), MSB first.
pub const CRC8_POLY: u8 = 0x1D;
/// Initial register value.
pub const CRC8_INIT: u8 = 0xFF;
/// Final XOR.
pub const CRC8_XOROUT: u8 = 0xFF;

/// One byte through the CRC register (MSB first, no reflection).
const fn update(mut crc: u8, byte: u8) -> u8 {
    crc ^= byte;
    let mut bit = 0;
    while bit < 8 {
        crc = if crc & 0x80 != 0 {
            (crc << 1) ^ CRC8_POLY
        } else {
            crc << 1
        };
        bit += 1;
    }
    crc
}

/// [`update`] of every register value with a zero byte, built at compile time: one byte
/// through the register is then one lookup, `TABLE[crc ^ byte]`, where the bit loop took
/// some 20 instructions per byte on the M4F. Every frame the node sends and every report it
/// checks goes through it (9 bytes each): measured in QEMU, the tick's bound fell by about
/// 3 400 instructions (docs/firmware.md).
// Indexing in a constant's evaluation: out of range would fail the build, never a run.
#[allow(clippy::indexing_slicing)]
const TABLE: [u8; 256] = {
    let mut table = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        table[i] = update(i as u8, 0);
        i += 1;
    }
    table
};

/// One byte through the CRC register, by [`TABLE`] (the same as [`update`]).
#[inline(always)]
fn step(crc: u8, byte: u8) -> u8 {
    // A u8 index into 256 entries: always there (the compiler drops the check).
    TABLE.get(usize::from(crc ^ byte)).copied().unwrap_or(0)
}

/// CRC-8/SAE-J1850 of `bytes`.
pub fn crc8_sae_j1850(bytes: &[u8]) -> u8 {
    bytes.iter().fold(CRC8_INIT, |crc, &b| step(crc, b)) ^ CRC8_XOROUT
}

/// The CRC stored in byte 7 of a protected frame: computed over the identifier's high byte,
/// its low byte, then payload bytes 0..=6 (docs/bus.md). For 11-bit identifiers the high byte
/// is `id >> 8` (0..=7); for 29-bit identifiers only the low 16 bits take part.
pub fn frame_crc(id: CanId, data: &[u8; 8]) -> u8 {
    let raw = id.raw();
    let crc = step(step(CRC8_INIT, (raw >> 8) as u8), raw as u8);
    data.iter().take(7).fold(crc, |crc, &b| step(crc, b)) ^ CRC8_XOROUT
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table is the bit loop, for every register value and byte.
    #[test]
    fn the_table_is_the_bit_loop() {
        for crc in 0..=255u8 {
            for byte in 0..=255u8 {
                assert_eq!(step(crc, byte), update(crc, byte), "{crc} {byte}");
            }
        }
    }

    #[test]
    fn check_values() {
        assert_eq!(crc8_sae_j1850(b"123456789"), 0x4B);
        assert_eq!(crc8_sae_j1850(b"0"), 0x71);
        assert_eq!(crc8_sae_j1850(b"01"), 0x28);
    }

    #[test]
    fn frame_crc_is_crc_of_id_then_payload() {
        let data = [1, 2, 3, 4, 5, 6, 7, 0xAA];
        let bytes = [0x03, 0x10, 1, 2, 3, 4, 5, 6, 7];
        assert_eq!(
            frame_crc(CanId::Standard(0x310), &data),
            crc8_sae_j1850(&bytes)
        );
    }
}
