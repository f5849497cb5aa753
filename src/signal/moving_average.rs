//! Causal moving average for the node: the mean of the last N samples (paper II-C smooths with
//! a moving average; this is its causal, streaming counterpart).
//!
//! No drift, by construction: the mean is recomputed from the stored window on every sample
//! (N adds and one multiply), instead of keeping a running sum that adds the new sample and
//! subtracts the oldest, whose rounding errors would accumulate without bound in `f32`.
//! For the small N the node uses (about 10) this is as cheap as the running-sum bookkeeping,
//! and the output depends only on the last N inputs, bit for bit.
use crate::image::{Image, ImageError, ImageReader, ImageWriter};

/// Configuration of a causal moving average over N samples (N >= 1), or over a shorter span
/// chosen at run time ([`MovingAverage::with_span`]). Holds 1/span.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovingAverage<const N: usize> {
    inv_n: f32,
    /// Samples averaged, 1..=N (N for [`MovingAverage::new`]).
    span: usize,
}

/// The span (1..=N); 1/span follows from it.
impl<const N: usize> Image for MovingAverage<N> {
    fn write(&self, w: &mut ImageWriter<'_>) {
        let Self { inv_n: _, span } = self;
        span.write(w);
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        let span = usize::read(r)?;
        Self::with_span(span).ok_or_else(|| r.out_of_range())
    }
}

impl<const N: usize> Default for MovingAverage<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> MovingAverage<N> {
    /// A moving average over N samples. N = 0 is a degenerate filter whose output is
    /// always 0.
    pub const fn new() -> Self {
        Self {
            inv_n: if N == 0 { 0.0 } else { 1.0 / N as f32 },
            span: N,
        }
    }

    /// A moving average over the last `span` samples, 1 <= span <= N (`None` otherwise). Its
    /// output is bit for bit that of a `MovingAverage<span>`: the samples sit in the same
    /// slots, and the unused slots add exact zeros after them.
    pub fn with_span(span: usize) -> Option<Self> {
        if span == 0 || span > N {
            return None;
        }
        Some(Self {
            inv_n: 1.0 / span as f32,
            span,
        })
    }

    /// Fills `state`'s window with `value`, as if the input had been `value` forever (the
    /// span's slots only: [`MovingAverageState::primed`] fills all N).
    pub fn prime(&self, state: &mut MovingAverageState<N>, value: f32) {
        *state = MovingAverageState::new();
        for slot in state.window.iter_mut().take(self.span) {
            *slot = value;
        }
        state.count = self.span;
    }

    /// Replaces `state`'s window with the span's last inputs: `input(k)` is the input `k`
    /// samples before the newest (k = 0 the newest, up to span - 1), exactly as if those
    /// samples had just been pushed in order (the same slots, so the same sums, bit for bit);
    /// the slots beyond the span hold 0, as [`Self::prime`] leaves them. For a span shorter than
    /// N, [`MovingAverageState::load`] (which fills all N) would leave inputs in slots that
    /// [`Self::process`] sums but never overwrites: a 4 Hz receiver's filters restarted on the
    /// dead-reckoned track after a gap put the position 5.6 m behind the car, for good
    /// (docs/findings.md).
    pub fn load(&self, state: &mut MovingAverageState<N>, mut input: impl FnMut(usize) -> f32) {
        let span = self.span.min(N);
        // `span` pushes from `next` fill slots next, next + 1, ... (mod span), oldest first,
        // and leave `next` where it was.
        let start = if state.next < span { state.next } else { 0 };
        let (window, beyond) = state.window.split_at_mut(span);
        let (older, newer) = window.split_at_mut(start.min(span));
        for (slot, k) in newer
            .iter_mut()
            .chain(older.iter_mut())
            .zip((0..span).rev())
        {
            *slot = input(k);
        }
        for slot in beyond {
            *slot = 0.0;
        }
        state.next = start;
        state.count = span;
    }

    /// Window length in samples.
    pub const fn len(&self) -> usize {
        self.span
    }

    /// True for the degenerate N = 0.
    pub const fn is_empty(&self) -> bool {
        N == 0
    }

    /// Group delay in samples: (span - 1) / 2.
    pub fn group_delay_samples(&self) -> f32 {
        (self.span as f32 - 1.0) * 0.5
    }

    /// Pushes `x` and returns the mean of the last `span` samples (of the `count` samples seen
    /// so far while fewer than `span` have arrived since a reset, so an unprimed filter does not ramp
    /// up from 0). Same units as `x`. A NaN input poisons the output for `span` samples.
    pub fn process(&self, state: &mut MovingAverageState<N>, x: f32) -> f32 {
        if let Some(slot) = state.window.get_mut(state.next) {
            *slot = x;
        }
        state.next += 1;
        if state.next >= self.span {
            state.next = 0;
        }
        if state.count < self.span {
            state.count += 1;
        }
        let sum: f32 = state.window.iter().sum();
        if state.count == self.span {
            sum * self.inv_n
        } else {
            // Unfilled slots are 0 after a reset, so `sum` is the sum of the `count` samples.
            sum / state.count as f32
        }
    }
}

/// The last N inputs of a [`MovingAverage<N>`].
#[derive(Debug, Clone, PartialEq)]
pub struct MovingAverageState<const N: usize> {
    window: [f32; N],
    /// Slot the next sample goes to.
    next: usize,
    /// Samples seen since the last reset, saturating at N.
    count: usize,
}

impl<const N: usize> Default for MovingAverageState<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> MovingAverageState<N> {
    /// Empty: the first outputs average the samples seen so far.
    pub const fn new() -> Self {
        Self {
            window: [0.0; N],
            next: 0,
            count: 0,
        }
    }

    /// Full window of `value`, as if the input had been `value` forever.
    pub const fn primed(value: f32) -> Self {
        Self {
            window: [value; N],
            next: 0,
            count: N,
        }
    }

    /// Refills the window with `value` (see [`MovingAverageState::primed`]), in place.
    pub fn prime(&mut self, value: f32) {
        self.load(|_| value);
    }

    /// Back to empty.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Replaces the window: `input(k)` is the input `k` samples before the newest (k = 0 the
    /// newest, up to N - 1), exactly as if those N samples had just been pushed in order (the
    /// same slots, so the same sums, bit for bit).
    pub fn load(&mut self, mut input: impl FnMut(usize) -> f32) {
        // N pushes from `next` fill slots next, next + 1, ... (mod N), oldest first, and leave
        // `next` where it was.
        let (older, newer) = self.window.split_at_mut(self.next.min(N));
        for (slot, k) in newer.iter_mut().chain(older.iter_mut()).zip((0..N).rev()) {
            *slot = input(k);
        }
        self.count = N;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A span of 3 in storage for 8: the loaded window averages the last three inputs and
    /// goes on as if they had been pushed (hand-derived: (3 + 4 + 5) / 3 = 4 after 5 is
    /// pushed), from any slot, and whatever the slots beyond the span held.
    #[test]
    fn load_fills_the_span_only() {
        let ma = MovingAverage::<8>::with_span(3).unwrap();
        let mut state = MovingAverageState::<8>::primed(100.0);
        for first in 0..3 {
            state.next = first;
            // input(k): k samples before the newest; the newest is 4.
            ma.load(&mut state, |k| 4.0 - k as f32);
            let mut pushed = MovingAverageState::<8>::new();
            for x in [2.0, 3.0, 4.0] {
                ma.process(&mut pushed, x);
            }
            assert_eq!(ma.process(&mut state, 5.0), 4.0);
            assert_eq!(ma.process(&mut pushed, 5.0), 4.0);
            assert_eq!(ma.process(&mut state, 6.0), 5.0);
        }
    }

    #[test]
    fn mean_of_last_n() {
        let ma = MovingAverage::<3>::new();
        let mut s = MovingAverageState::new();
        let out: Vec<f32> = [3.0, 6.0, 9.0, 12.0, 0.0]
            .iter()
            .map(|&x| ma.process(&mut s, x))
            .collect();
        // 3/1, (3+6)/2, (3+6+9)/3, (6+9+12)/3, (9+12+0)/3
        assert_eq!(out, vec![3.0, 4.5, 6.0, 9.0, 7.0]);
    }

    #[test]
    fn a_loaded_window_is_a_pushed_one() {
        let ma = MovingAverage::<10>::new();
        let x: Vec<f32> = (0..25).map(|i| (i * i) as f32 * 0.37 - 3.0).collect();
        // From the same state (8 samples in), ten samples pushed or loaded.
        let mut pushed = MovingAverageState::new();
        for v in &x[..8] {
            ma.process(&mut pushed, *v);
        }
        let mut loaded = pushed.clone();
        for v in &x[8..18] {
            ma.process(&mut pushed, *v);
        }
        loaded.load(|k| x[17 - k]);
        assert_eq!(loaded, pushed);
        for v in &x[18..] {
            assert_eq!(
                ma.process(&mut loaded, *v).to_bits(),
                ma.process(&mut pushed, *v).to_bits()
            );
        }
        let mut primed = MovingAverageState::<10>::new();
        primed.prime(4.0);
        assert_eq!(primed, MovingAverageState::primed(4.0));
    }

    #[test]
    fn primed_and_no_drift() {
        let ma = MovingAverage::<10>::new();
        let mut s = MovingAverageState::primed(5.0);
        assert_eq!(ma.process(&mut s, 5.0), 5.0);
        // After a million noisy samples, a constant input must give the constant again: a
        // running sum would have drifted.
        for k in 0..1_000_000u32 {
            ma.process(&mut s, (k as f32 * 0.618_034).sin() * 1.0e3 + 1.0e3);
        }
        let mut y = 0.0;
        for _ in 0..10 {
            y = ma.process(&mut s, 0.1);
        }
        assert!((y - 0.1).abs() <= 1e-7, "{y}");
    }
}
