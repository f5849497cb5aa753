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

/// CRC-8/SAE-J1850 of `bytes`.
pub fn crc8_sae_j1850(bytes: &[u8]) -> u8 {
    bytes.iter().fold(CRC8_INIT, |crc, &b| update(crc, b)) ^ CRC8_XOROUT
}

/// The CRC stored in byte 7 of a protected frame: computed over the identifier's high byte,
/// its low byte, then payload bytes 0..=6 (docs/bus.md). For 11-bit identifiers the high byte
/// is `id >> 8` (0..=7); for 29-bit identifiers only the low 16 bits take part.
pub fn frame_crc(id: CanId, data: &[u8; 8]) -> u8 {
    let raw = id.raw();
    let crc = update(update(CRC8_INIT, (raw >> 8) as u8), raw as u8);
    data.iter().take(7).fold(crc, |crc, &b| update(crc, b)) ^ CRC8_XOROUT
}

#[cfg(test)]
mod tests {
    use super::*;

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
