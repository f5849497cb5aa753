//! FIR lowpass: offline design (f64) and a streaming filter for the node (f32).
//!
//! The paper (II-C) filters every resampled signal with a "20th order FIR low pass filter",
//! i.e. 21 taps. [`design_lowpass`] is the windowed-sinc method with a Hamming window scaled to
//! unit DC gain, the default of MATLAB `fir1` and of `scipy.signal.firwin(numtaps, cutoff, fs=fs)`,
//! which it equals to ~1e-16 (see `host-tests/tests/signal.rs`).
//!
//! [`Fir`] holds the taps (configuration, immutable) and [`FirState`] the delay line (state).
//! The delay line is a doubled circular buffer: each sample is written twice, at `i` and
//! `i + N`, so the last N samples are always the contiguous slice `[i, i + N)` and the dot
//! product is one straight loop, with no modulo and no wrap test per tap.
use crate::image::{Image, ImageError, ImageReader, ImageWriter};

/// Why a filter design or configuration was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FilterError {
    /// No taps (numtaps = 0).
    NoTaps,
    /// The sampling frequency is not finite and positive.
    InvalidSampleRate,
    /// The cutoff is not finite or not strictly between 0 and the Nyquist frequency fs/2
    /// (`firwin` rejects the same).
    CutoffOutOfRange,
    /// A tap is NaN or infinite.
    NonFiniteTap,
    /// The taps sum to zero or a non-finite value, so unit DC gain cannot be reached.
    ZeroDcGain,
}

/// Designs a linear-phase lowpass FIR filter into `taps` (its length is numtaps, odd or even):
/// ideal lowpass `h[i] = c sinc(c (i - (numtaps-1)/2))` with `c = cutoff_hz / (fs_hz/2)`, times
/// the symmetric Hamming window `0.54 - 0.46 cos(2 pi i / (numtaps-1))`, scaled so the taps sum
/// to 1 (unit gain at 0 Hz).
///
/// Equal to `scipy.signal.firwin(numtaps, cutoff_hz, fs=fs_hz)` (window `hamming`,
/// `pass_zero=True`, `scale=True`); like `firwin`, even numtaps are accepted for a lowpass. The
/// first half is computed and mirrored, so the taps are exactly symmetric (exact linear phase).
/// Units: Hz for both frequencies. f64, offline; not for the node's tick.
pub fn design_lowpass(taps: &mut [f64], cutoff_hz: f64, fs_hz: f64) -> Result<(), FilterError> {
    let numtaps = taps.len();
    if numtaps == 0 {
        return Err(FilterError::NoTaps);
    }
    if !(fs_hz.is_finite() && fs_hz > 0.0) {
        return Err(FilterError::InvalidSampleRate);
    }
    let nyquist_hz = 0.5 * fs_hz;
    if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < nyquist_hz) {
        return Err(FilterError::CutoffOutOfRange);
    }
    let c = cutoff_hz / nyquist_hz;
    let alpha = 0.5 * (numtaps as f64 - 1.0);
    let half = numtaps.div_ceil(2);
    for i in 0..half {
        let m = i as f64 - alpha;
        let window = if numtaps == 1 {
            // scipy's get_window returns ones for M = 1.
            1.0
        } else {
            0.54 - 0.46 * libm::cos(2.0 * core::f64::consts::PI * i as f64 / (numtaps as f64 - 1.0))
        };
        let h = c * sinc(c * m) * window;
        if let Some(t) = taps.get_mut(i) {
            *t = h;
        }
        if let Some(t) = taps.get_mut(numtaps - 1 - i) {
            *t = h;
        }
    }
    let dc: f64 = taps.iter().sum();
    if !(dc.is_finite() && dc != 0.0) {
        return Err(FilterError::ZeroDcGain);
    }
    for t in taps.iter_mut() {
        *t /= dc;
    }
    Ok(())
}

/// Normalised sinc, sin(pi x) / (pi x), 1 at 0 (numpy's `sinc`).
fn sinc(x: f64) -> f64 {
    if x == 0.0 {
        1.0
    } else {
        let y = core::f64::consts::PI * x;
        libm::sin(y) / y
    }
}

/// The taps and how many are in use; [`Fir::from_taps`] checks the taps again on the way in,
/// and the taps after the ones in use must be zero.
impl<const N: usize> Image for Fir<N> {
    fn write(&self, w: &mut ImageWriter<'_>) {
        let Self { taps, len } = self;
        taps.write(w);
        len.write(w);
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        let taps = <[f32; N]>::read(r)?;
        let mut fir = Self::from_taps(taps).map_err(|_| r.out_of_range())?;
        let len = usize::read(r)?;
        let unused = taps.get(len..).filter(|_| len >= 1);
        match unused {
            Some(rest) if rest.iter().all(|t| *t == 0.0) => fir.len = len,
            _ => return Err(r.out_of_range()),
        }
        Ok(fir)
    }
}

/// Streaming FIR filter configuration: N taps in `f32`, `y[n] = sum_k taps[k] x[n-k]`.
/// Immutable; the delay line lives in [`FirState`].
#[derive(Debug, Clone, PartialEq)]
pub struct Fir<const N: usize> {
    taps: [f32; N],
    /// Taps in use, from the first; the rest are zero (see [`Fir::lowpass_len`]).
    len: usize,
}

impl<const N: usize> Fir<N> {
    /// Takes f64 taps (from [`design_lowpass`] or elsewhere), rounding each to `f32` once.
    pub fn from_taps_f64(taps: &[f64; N]) -> Result<Self, FilterError> {
        if N == 0 {
            return Err(FilterError::NoTaps);
        }
        if taps.iter().any(|t| !t.is_finite()) {
            return Err(FilterError::NonFiniteTap);
        }
        Ok(Self {
            taps: taps.map(|t| t as f32),
            len: N,
        })
    }

    /// Takes `f32` taps as they are.
    pub fn from_taps(taps: [f32; N]) -> Result<Self, FilterError> {
        if N == 0 {
            return Err(FilterError::NoTaps);
        }
        if taps.iter().any(|t| !t.is_finite()) {
            return Err(FilterError::NonFiniteTap);
        }
        Ok(Self { taps, len: N })
    }

    /// [`design_lowpass`] with N taps (f64), then [`Fir::from_taps_f64`]. Hz.
    pub fn lowpass(cutoff_hz: f64, fs_hz: f64) -> Result<Self, FilterError> {
        let mut taps = [0.0_f64; N];
        design_lowpass(&mut taps, cutoff_hz, fs_hz)?;
        Self::from_taps_f64(&taps)
    }

    /// The taps, `taps[0]` multiplying the newest sample.
    pub fn taps(&self) -> &[f32; N] {
        &self.taps
    }

    /// Group delay of a symmetric (linear-phase) design, in samples: (len - 1) / 2 with len
    /// the taps in use (10 samples = 0.1 s at 100 Hz for the paper's 21 taps). Half-integer
    /// for an even length.
    pub fn group_delay_samples(&self) -> f32 {
        (self.len as f32 - 1.0) * 0.5
    }

    /// [`design_lowpass`] with `len` taps (1 <= len <= N) in the first `len` taps and zeros
    /// after: a shorter filter in this delay line, for a filter whose length is chosen at run
    /// time (the node's GNSS lowpass follows the receiver's rate). Its output is bit for bit
    /// that of a `Fir<len>` (the zero taps add exact zeros last); its group delay is
    /// (len - 1) / 2. `NoTaps` for len 0 or above N.
    pub fn lowpass_len(len: usize, cutoff_hz: f64, fs_hz: f64) -> Result<Self, FilterError> {
        let mut taps = [0.0_f64; N];
        let used = taps
            .get_mut(..len)
            .filter(|t| !t.is_empty())
            .ok_or(FilterError::NoTaps)?;
        design_lowpass(used, cutoff_hz, fs_hz)?;
        let mut f = Self::from_taps_f64(&taps)?;
        f.len = len;
        Ok(f)
    }

    /// Taps in use (N, or the `len` of [`Fir::lowpass_len`]).
    pub fn len(&self) -> usize {
        self.len
    }

    /// True for the degenerate `Fir<0>` (which no constructor returns).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Pushes one sample into the delay line and returns the filtered output. Same units as
    /// `x`. N multiply-adds in a fixed order (newest sample first), so the result is
    /// bit-identical on every target. A NaN input poisons the output for the next N samples:
    /// the caller gates inputs.
    #[inline]
    pub fn process(&self, state: &mut FirState<N>, x: f32) -> f32 {
        if N == 0 {
            return 0.0;
        }
        let Some(window) = state.push(x) else {
            return f32::NAN;
        };
        let mut acc = 0.0_f32;
        for (t, v) in self.taps.iter().zip(window.iter()) {
            acc += t * v;
        }
        acc
    }
}

impl<const N: usize> Fir<N> {
    /// [`Fir::process`] on two signals at once (the two axes of a position): the same
    /// outputs, bit for bit, for the cost of about one and a half (the taps are loaded once).
    #[inline]
    pub fn process_pair(
        &self,
        (state_a, state_b): (&mut FirState<N>, &mut FirState<N>),
        (a, b): (f32, f32),
    ) -> (f32, f32) {
        let (Some(wa), Some(wb)) = (state_a.push(a), state_b.push(b)) else {
            return (f32::NAN, f32::NAN);
        };
        let (mut acc_a, mut acc_b) = (0.0_f32, 0.0_f32);
        for ((t, va), vb) in self.taps.iter().zip(wa.iter()).zip(wb.iter()) {
            acc_a += t * va;
            acc_b += t * vb;
        }
        (acc_a, acc_b)
    }
}

/// Delay line of a [`Fir<N>`]: the last N inputs, stored twice (doubled circular buffer).
#[derive(Debug, Clone, PartialEq)]
pub struct FirState<const N: usize> {
    /// `line[0]` and `line[1]` are the two copies, used as one flat slice of 2N.
    line: [[f32; N]; 2],
    /// Index (0..N) of the newest sample in the first copy.
    newest: usize,
}

impl<const N: usize> Default for FirState<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FirState<N> {
    /// All-zero history: the output ramps up from 0 over N samples.
    pub const fn new() -> Self {
        Self {
            line: [[0.0; N]; 2],
            newest: 0,
        }
    }

    /// History filled with `value`, as if the input had been `value` forever: the output starts
    /// at `value * sum(taps)` (= `value` to f32 rounding for a unit-DC-gain design). Use this
    /// when a filter starts on a live stream (e.g. GNSS position), so it does not ramp from 0.
    pub const fn primed(value: f32) -> Self {
        Self {
            line: [[value; N]; 2],
            newest: 0,
        }
    }

    /// Refills the history with `value` (see [`FirState::primed`]), in place.
    pub fn prime(&mut self, value: f32) {
        self.load(|_| value);
    }

    /// Back to all zeros.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Pushes `x` and returns the last N inputs, newest first (as [`Fir::process`] does before
    /// its dot product); `None` only for N = 0.
    #[inline(always)]
    fn push(&mut self, x: f32) -> Option<&[f32; N]> {
        if N == 0 {
            return None;
        }
        let i = if self.newest == 0 {
            N - 1
        } else {
            self.newest - 1
        };
        self.newest = i;
        let line = self.line.as_flattened_mut();
        if let Some(slot) = line.get_mut(i) {
            *slot = x;
        }
        if let Some(slot) = line.get_mut(i + N) {
            *slot = x;
        }
        // line[i + k] = x[n - k] for k = 0..N; i < N so the slice is always in bounds.
        line.get(i..i + N).and_then(|s| s.try_into().ok())
    }

    /// Replaces the history: `input(k)` is the input `k` samples before the newest (k = 0 the
    /// newest, up to N - 1), as if those N samples had just been pushed. N calls, no filtering.
    pub fn load(&mut self, mut input: impl FnMut(usize) -> f32) {
        self.newest = 0;
        let [first, second] = &mut self.line;
        for (k, (a, b)) in first.iter_mut().zip(second.iter_mut()).enumerate() {
            let x = input(k);
            *a = x;
            *b = x;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn impulse_response_is_the_taps() {
        let fir = Fir::<5>::from_taps([1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        let mut s = FirState::new();
        let out: Vec<f32> = (0..8)
            .map(|n| fir.process(&mut s, if n == 0 { 1.0 } else { 0.0 }))
            .collect();
        assert_eq!(out, vec![1.0, 2.0, 3.0, 4.0, 5.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn primed_state_outputs_value_at_once() {
        let fir = Fir::<21>::lowpass(5.0, 100.0).unwrap();
        let mut s = FirState::primed(12.5);
        let y = fir.process(&mut s, 12.5);
        assert!((y - 12.5).abs() < 12.5 * 1e-6, "{y}");
        s.reset();
        assert!(fir.process(&mut s, 12.5).abs() < 1.0);
    }

    /// Deterministic inputs in the node's range (positions in metres).
    fn signal(n: usize, seed: u32) -> Vec<f32> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                (x % 200_000) as f32 * 0.01 - 1000.0
            })
            .collect()
    }

    #[test]
    fn pair_is_two_single_filters_bit_for_bit() {
        let fir = Fir::<21>::lowpass(2.0, 100.0).unwrap();
        let (a, b) = (signal(300, 7), signal(300, 11));
        let (mut sa, mut sb) = (FirState::new(), FirState::new());
        let (mut ra, mut rb) = (FirState::new(), FirState::new());
        for (x, y) in a.iter().zip(&b) {
            let pair = fir.process_pair((&mut sa, &mut sb), (*x, *y));
            let single = (fir.process(&mut ra, *x), fir.process(&mut rb, *y));
            assert_eq!(pair.0.to_bits(), single.0.to_bits());
            assert_eq!(pair.1.to_bits(), single.1.to_bits());
        }
    }

    #[test]
    fn a_loaded_history_is_a_pushed_one() {
        let fir = Fir::<21>::lowpass(2.0, 100.0).unwrap();
        let x = signal(40, 3);
        let mut pushed = FirState::new();
        for v in &x[..30] {
            fir.process(&mut pushed, *v);
        }
        let mut loaded = FirState::primed(5.0);
        loaded.load(|k| x[29 - k]);
        for v in &x[30..] {
            assert_eq!(
                fir.process(&mut loaded, *v).to_bits(),
                fir.process(&mut pushed, *v).to_bits()
            );
        }
        let mut primed = FirState::<21>::new();
        primed.prime(2.5);
        assert_eq!(primed, FirState::primed(2.5));
    }

    #[test]
    fn design_rejects_bad_input() {
        let mut t = [0.0; 5];
        assert_eq!(design_lowpass(&mut [], 1.0, 10.0), Err(FilterError::NoTaps));
        assert_eq!(
            design_lowpass(&mut t, 5.0, 10.0),
            Err(FilterError::CutoffOutOfRange)
        );
        assert_eq!(
            design_lowpass(&mut t, 0.0, 10.0),
            Err(FilterError::CutoffOutOfRange)
        );
        assert_eq!(
            design_lowpass(&mut t, 1.0, 0.0),
            Err(FilterError::InvalidSampleRate)
        );
        assert_eq!(
            design_lowpass(&mut t, f64::NAN, 10.0),
            Err(FilterError::CutoffOutOfRange)
        );
        assert!(Fir::<0>::from_taps([]).is_err());
        assert_eq!(
            Fir::<2>::from_taps_f64(&[1.0, f64::NAN]),
            Err(FilterError::NonFiniteTap)
        );
    }
}
