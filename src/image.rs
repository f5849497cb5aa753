//! The node's configuration as a flat array of 32-bit words: the "configuration image".
//!
//! The firmware build reads the car's model file with the host's reader (crate
//! `catmodel-model-file`), discretizes and designs everything in f64 there, rounds it to f32
//! once, and bakes the image's words into flash (`catmodel-firmware`'s build script). At boot the
//! node reads the image back into a [`crate::node::NodeConfig`], which checks every word (finite,
//! in range, the right length); host replay builds the same configuration from the same file
//! in memory, so board, QEMU and host run bit-identical numbers. No matrix exponential, no
//! filter design and no f64 arithmetic is left for the MCU at boot.
//!
//! Each configuration type writes and reads its own fields ([`Image`]); a type's `read` builds
//! the value with an exhaustive struct literal and its `write` destructures it exhaustively, so a
//! field added to a configuration type cannot be forgotten here (it does not compile), and the
//! round trip is tested.
//!
//! Layout: `MAGIC`, `VERSION`, then the fields in declaration order; f32 as their bits, `u64` as
//! two words (low first), `bool` and `Option` tags as 0/1, enums as their index.
use nalgebra::SMatrix;

/// First word of every image: `b"CMCI"` little-endian ("catmodel configuration image").
pub const MAGIC: u32 = u32::from_le_bytes(*b"CMCI");
/// Layout version; bumped when any configuration type changes its fields.
pub const VERSION: u32 = 4;

/// Why an image was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImageError {
    /// The words ran out before the configuration was complete.
    TooShort,
    /// Words are left over after the configuration (a different layout).
    TrailingWords {
        /// Index of the first unused word.
        at: usize,
    },
    /// The first word is not [`MAGIC`].
    BadMagic,
    /// Another layout version.
    BadVersion {
        /// The version found.
        found: u32,
    },
    /// A word that must be a finite f32 is not.
    NotFinite {
        /// Its index.
        at: usize,
    },
    /// A word outside its field's range (a tag that is not 0/1, a delay beyond its line).
    OutOfRange {
        /// Its index.
        at: usize,
    },
}

/// Appends words; counts the words it could not store (see [`ImageWriter::overflowed`]).
#[derive(Debug)]
pub struct ImageWriter<'a> {
    words: &'a mut [u32],
    len: usize,
}

impl<'a> ImageWriter<'a> {
    /// A writer into `words`.
    pub fn new(words: &'a mut [u32]) -> Self {
        Self { words, len: 0 }
    }

    /// Appends one word.
    pub fn word(&mut self, w: u32) {
        if let Some(slot) = self.words.get_mut(self.len) {
            *slot = w;
        }
        self.len = self.len.saturating_add(1);
    }

    /// Words written so far (including any that did not fit).
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether nothing was written.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether more words were written than the buffer holds.
    pub fn overflowed(&self) -> bool {
        self.len > self.words.len()
    }
}

/// Reads words in order, checking each.
#[derive(Debug)]
pub struct ImageReader<'a> {
    words: &'a [u32],
    at: usize,
}

impl<'a> ImageReader<'a> {
    /// A reader over `words`.
    pub fn new(words: &'a [u32]) -> Self {
        Self { words, at: 0 }
    }

    /// The next word.
    pub fn word(&mut self) -> Result<u32, ImageError> {
        let w = *self.words.get(self.at).ok_or(ImageError::TooShort)?;
        self.at += 1;
        Ok(w)
    }

    /// Index of the next word (for errors).
    pub fn position(&self) -> usize {
        self.at
    }

    /// An error for the word just read.
    pub fn out_of_range(&self) -> ImageError {
        ImageError::OutOfRange {
            at: self.at.saturating_sub(1),
        }
    }

    /// Succeeds only if every word was read.
    pub fn finish(&self) -> Result<(), ImageError> {
        if self.at == self.words.len() {
            Ok(())
        } else {
            Err(ImageError::TrailingWords { at: self.at })
        }
    }
}

/// A configuration value that has a place in the image.
pub trait Image: Sized {
    /// Appends this value's words.
    fn write(&self, w: &mut ImageWriter<'_>);
    /// Reads a value written by [`Image::write`], checking every word.
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError>;
}

impl Image for u32 {
    fn write(&self, w: &mut ImageWriter<'_>) {
        w.word(*self);
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        r.word()
    }
}

impl Image for i32 {
    fn write(&self, w: &mut ImageWriter<'_>) {
        w.word(self.cast_unsigned());
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        Ok(r.word()?.cast_signed())
    }
}

impl Image for u64 {
    fn write(&self, w: &mut ImageWriter<'_>) {
        w.word(*self as u32);
        w.word((*self >> 32) as u32);
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        let lo = u64::from(r.word()?);
        let hi = u64::from(r.word()?);
        Ok(lo | (hi << 32))
    }
}

impl Image for u16 {
    fn write(&self, w: &mut ImageWriter<'_>) {
        w.word(u32::from(*self));
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        u16::try_from(r.word()?).map_err(|_| r.out_of_range())
    }
}

impl Image for u8 {
    fn write(&self, w: &mut ImageWriter<'_>) {
        w.word(u32::from(*self));
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        u8::try_from(r.word()?).map_err(|_| r.out_of_range())
    }
}

impl Image for usize {
    fn write(&self, w: &mut ImageWriter<'_>) {
        w.word(u32::try_from(*self).unwrap_or(u32::MAX));
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        usize::try_from(r.word()?).map_err(|_| r.out_of_range())
    }
}

impl Image for bool {
    fn write(&self, w: &mut ImageWriter<'_>) {
        w.word(u32::from(*self));
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        match r.word()? {
            0 => Ok(false),
            1 => Ok(true),
            _ => Err(r.out_of_range()),
        }
    }
}

/// Finite values only: a NaN or an infinity in a configuration is a corrupt image.
impl Image for f32 {
    fn write(&self, w: &mut ImageWriter<'_>) {
        w.word(self.to_bits());
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        let v = f32::from_bits(r.word()?);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(ImageError::NotFinite {
                at: r.position().saturating_sub(1),
            })
        }
    }
}

impl<T: Image> Image for Option<T> {
    fn write(&self, w: &mut ImageWriter<'_>) {
        match self {
            None => false.write(w),
            Some(v) => {
                true.write(w);
                v.write(w);
            }
        }
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        if bool::read(r)? {
            Ok(Some(T::read(r)?))
        } else {
            Ok(None)
        }
    }
}

impl<A: Image, B: Image> Image for (A, B) {
    fn write(&self, w: &mut ImageWriter<'_>) {
        self.0.write(w);
        self.1.write(w);
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        Ok((A::read(r)?, B::read(r)?))
    }
}

impl<T: Image + Copy + Default, const N: usize> Image for [T; N] {
    fn write(&self, w: &mut ImageWriter<'_>) {
        for v in self {
            v.write(w);
        }
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        let mut out = [T::default(); N];
        for v in out.iter_mut() {
            *v = T::read(r)?;
        }
        Ok(out)
    }
}

/// Column-major, as nalgebra stores it.
impl<const R: usize, const C: usize> Image for SMatrix<f32, R, C> {
    fn write(&self, w: &mut ImageWriter<'_>) {
        for v in self.iter() {
            v.write(w);
        }
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        let mut m = SMatrix::<f32, R, C>::zeros();
        for v in m.iter_mut() {
            *v = f32::read(r)?;
        }
        Ok(m)
    }
}

/// `value` as a complete image: [`MAGIC`], [`VERSION`], then its words. Returns the number of
/// words; the image is complete only if that is at most `words.len()`.
pub fn encode<T: Image>(value: &T, words: &mut [u32]) -> usize {
    let mut w = ImageWriter::new(words);
    w.word(MAGIC);
    w.word(VERSION);
    value.write(&mut w);
    w.len()
}

/// Reads a complete image written by [`encode`].
pub fn decode<T: Image>(words: &[u32]) -> Result<T, ImageError> {
    let mut r = ImageReader::new(words);
    if r.word()? != MAGIC {
        return Err(ImageError::BadMagic);
    }
    let version = r.word()?;
    if version != VERSION {
        return Err(ImageError::BadVersion { found: version });
    }
    let value = T::read(&mut r)?;
    r.finish()?;
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalars_round_trip_and_nan_is_refused() {
        let value: (u64, (Option<f32>, [i32; 3])) =
            (0x1234_5678_9ABC_DEF0, (Some(-1.5), [-7, 0, i32::MAX]));
        let mut words = [0u32; 16];
        let n = encode(&value, &mut words);
        assert_eq!(n, 2 + 2 + 2 + 3);
        let back: (u64, (Option<f32>, [i32; 3])) = decode(&words[..n]).unwrap();
        assert_eq!(back, value);
        // Too short, trailing words, magic, version, a NaN, a bad tag.
        assert_eq!(decode::<u64>(&words[..3]), Err(ImageError::TooShort));
        let mut long = [0u32; 5];
        let n = encode(&7u32, &mut long);
        assert_eq!(
            decode::<u32>(&long[..n + 1]),
            Err(ImageError::TrailingWords { at: n })
        );
        assert_eq!(decode::<u32>(&[0, VERSION, 1]), Err(ImageError::BadMagic));
        assert_eq!(
            decode::<u32>(&[MAGIC, 99, 1]),
            Err(ImageError::BadVersion { found: 99 })
        );
        assert_eq!(
            decode::<f32>(&[MAGIC, VERSION, f32::NAN.to_bits()]),
            Err(ImageError::NotFinite { at: 2 })
        );
        assert_eq!(
            decode::<Option<u32>>(&[MAGIC, VERSION, 2, 0]),
            Err(ImageError::OutOfRange { at: 2 })
        );
    }

    #[test]
    fn a_short_buffer_reports_the_length_it_needs() {
        let mut words = [0u32; 3];
        assert_eq!(encode(&[1u32, 2, 3], &mut words), 5);
    }
}
