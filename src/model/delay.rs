//! Pure input delay `u[k - d]`: the discrete form of `e^{-delay_s s}` when `delay_s` is a
//! whole number `d` of samples (eq 5: 0.42 s = 21 samples at 20 ms).
//!
//! [`DelayLine`] is the configuration (the delay, checked against the capacity `CAP`);
//! [`DelayLineState`] is the ring buffer of f32 inputs. The state is `Copy`, so the horizon
//! predictor can copy it and roll a model forward without touching the live state.
//! No allocation, no panics: a state built for a longer delay line still works (the read
//! position wraps modulo the configured delay).

use super::tf::ModelError;

/// A delay of `delay_samples <= CAP` samples (configuration, immutable).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DelayLine<const CAP: usize> {
    delay_samples: usize,
}

/// The last `delay_samples` inputs, oldest at `head`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DelayLineState<const CAP: usize> {
    buf: [f32; CAP],
    head: usize,
}

impl<const CAP: usize> DelayLine<CAP> {
    /// No delay (pass-through); valid for every `CAP`, including 0.
    pub const NONE: Self = Self { delay_samples: 0 };

    /// A delay of `delay_samples`; [`ModelError::DelayTooLong`] if it exceeds `CAP`.
    pub const fn new(delay_samples: usize) -> Result<Self, ModelError> {
        if delay_samples > CAP {
            return Err(ModelError::DelayTooLong {
                delay_samples,
                capacity: CAP,
            });
        }
        Ok(Self { delay_samples })
    }

    /// The delay, samples.
    pub const fn delay_samples(&self) -> usize {
        self.delay_samples
    }

    /// A state that behaves as if `value` had been the input forever.
    pub const fn state_primed(&self, value: f32) -> DelayLineState<CAP> {
        DelayLineState {
            buf: [value; CAP],
            head: 0,
        }
    }

    /// Feeds `x`, returns the input of `delay_samples` calls ago (or of the priming value
    /// before that). A delay of 0 returns `x`.
    #[inline]
    pub fn push(&self, state: &mut DelayLineState<CAP>, x: f32) -> f32 {
        if self.delay_samples == 0 {
            return x;
        }
        // Note: `head < delay_samples` unless the state came from another configuration;
        // wrapping keeps even that case in bounds and panic-free.
        let head = state.head % self.delay_samples;
        let y = match state.buf.get_mut(head) {
            Some(slot) => core::mem::replace(slot, x),
            None => x,
        };
        state.head = if head + 1 == self.delay_samples {
            0
        } else {
            head + 1
        };
        y
    }

    /// The inputs in flight, in the order `push` will return them: two contiguous pieces (the
    /// ring from its head, then its start).
    pub fn in_flight<'s>(&self, state: &'s DelayLineState<CAP>) -> (&'s [f32], &'s [f32]) {
        let line = state.buf.get(..self.delay_samples).unwrap_or(&[]);
        // Note: `head < delay_samples` unless the state came from another configuration (see
        // `push`); the modulo keeps even that case consistent with `push`.
        let head = state.head.checked_rem(self.delay_samples).unwrap_or(0);
        let (older, newer) = line.split_at(head.min(line.len()));
        (newer, older)
    }

    /// The value `push` will return `k` calls from now (`k < delay_samples`) without changing
    /// the state: the input already in flight. `None` for `k >= delay_samples`.
    pub fn peek(&self, state: &DelayLineState<CAP>, k: usize) -> Option<f32> {
        if k >= self.delay_samples {
            return None;
        }
        let idx = (state.head % self.delay_samples + k) % self.delay_samples;
        state.buf.get(idx).copied()
    }
}

impl<const CAP: usize> DelayLineState<CAP> {
    /// A zeroed state.
    pub const fn new() -> Self {
        Self {
            buf: [0.0; CAP],
            head: 0,
        }
    }
}

impl<const CAP: usize> Default for DelayLineState<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delays_by_exactly_d() {
        let line = DelayLine::<8>::new(3).unwrap();
        let mut s = line.state_primed(-1.0);
        let out: Vec<f32> = (0..7).map(|i| line.push(&mut s, i as f32)).collect();
        assert_eq!(out, [-1.0, -1.0, -1.0, 0.0, 1.0, 2.0, 3.0]);
        assert_eq!(line.peek(&s, 0), Some(4.0));
        assert_eq!(line.peek(&s, 2), Some(6.0));
        assert_eq!(line.peek(&s, 3), None);
    }

    #[test]
    fn in_flight_is_what_push_returns_next() {
        let line = DelayLine::<8>::new(5).unwrap();
        let mut s = line.state_primed(0.0);
        for i in 1..=7 {
            line.push(&mut s, i as f32);
        }
        let (a, b) = line.in_flight(&s);
        let in_flight: Vec<f32> = a.iter().chain(b).copied().collect();
        let pushed: Vec<f32> = (0..5).map(|_| line.push(&mut s, -1.0)).collect();
        assert_eq!(in_flight, pushed);
        assert_eq!(pushed, [3.0, 4.0, 5.0, 6.0, 7.0]);
        let none = DelayLine::<8>::NONE;
        assert_eq!(none.in_flight(&none.state_primed(1.0)), (&[][..], &[][..]));
    }

    #[test]
    fn zero_delay_passes_through_and_capacity_is_checked() {
        let line = DelayLine::<4>::new(0).unwrap();
        let mut s = line.state_primed(9.0);
        assert_eq!(line.push(&mut s, 2.5), 2.5);
        assert_eq!(
            DelayLine::<4>::new(5),
            Err(ModelError::DelayTooLong {
                delay_samples: 5,
                capacity: 4
            })
        );
        let full = DelayLine::<4>::new(4).unwrap();
        let mut s = full.state_primed(0.0);
        let out: Vec<f32> = (1..=6).map(|i| full.push(&mut s, i as f32)).collect();
        assert_eq!(out, [0.0, 0.0, 0.0, 0.0, 1.0, 2.0]);
    }
}
