//! Rolling-counter checking of the protected inputs (Dataspeed ds_dbw style): every frame of a
//! message carries a 4-bit counter that the sender increments by one per frame, modulo 16.
//!
//! - A counter equal to the previous one is **stuck**: the sender's software has hung while its
//!   CAN controller repeats the last frame. The frame is rejected (the receiver requires the
//!   counter to change) and counted.
//! - A counter that skipped values is a **jump**: frames were lost. The frame itself is valid
//!   and newer, so it is accepted, and the jump is counted with the number of missed frames.
//! - The first frame (or the first after [`CounterChecker::reset`], e.g. after the input timed
//!   out) is accepted without comparison.
//!
//! Configuration-free state; one checker per input message.

/// Counter modulus: 4 bits.
pub const COUNTER_MODULUS: u8 = 16;

/// Verdict on one frame's counter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CounterCheck {
    /// No previous counter to compare with: accepted.
    First,
    /// Exactly one more than the previous: accepted.
    InSequence,
    /// `missed` frames were lost (1..=14): accepted, counted.
    Jump {
        /// Frames missing between the previous counter and this one.
        missed: u8,
    },
    /// Same as the previous counter: rejected, counted.
    Stuck,
}

impl CounterCheck {
    /// Whether the frame may be used.
    pub const fn accepted(self) -> bool {
        !matches!(self, CounterCheck::Stuck)
    }
    /// Whether the node counts this as a counter error (stuck or jump).
    pub const fn is_error(self) -> bool {
        matches!(self, CounterCheck::Stuck | CounterCheck::Jump { .. })
    }
}

/// The state of one input's counter check, with saturating event counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CounterChecker {
    last: Option<u8>,
    /// Frames rejected because the counter did not change (saturating).
    pub stuck_count: u32,
    /// Jumps seen (saturating).
    pub jump_count: u32,
    /// Frames missed in all jumps (saturating).
    pub missed_frames: u32,
}

impl CounterChecker {
    /// A checker that has seen no frame.
    pub const fn new() -> Self {
        Self {
            last: None,
            stuck_count: 0,
            jump_count: 0,
            missed_frames: 0,
        }
    }

    /// Checks the counter of a frame that passed its CRC (only the low 4 bits are used).
    pub fn check(&mut self, counter: u8) -> CounterCheck {
        let counter = counter % COUNTER_MODULUS;
        let verdict = match self.last {
            None => CounterCheck::First,
            Some(last) => {
                let step = counter.wrapping_sub(last) % COUNTER_MODULUS;
                match step {
                    0 => CounterCheck::Stuck,
                    1 => CounterCheck::InSequence,
                    n => CounterCheck::Jump { missed: n - 1 },
                }
            }
        };
        match verdict {
            CounterCheck::Stuck => self.stuck_count = self.stuck_count.saturating_add(1),
            CounterCheck::Jump { missed } => {
                self.jump_count = self.jump_count.saturating_add(1);
                self.missed_frames = self.missed_frames.saturating_add(u32::from(missed));
                self.last = Some(counter);
            }
            CounterCheck::First | CounterCheck::InSequence => self.last = Some(counter),
        }
        verdict
    }

    /// Forgets the previous counter (the next frame is [`CounterCheck::First`]); the event
    /// counts are kept.
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// The last accepted counter.
    pub const fn last(&self) -> Option<u8> {
        self.last
    }
}
