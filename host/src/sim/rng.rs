//! Portable random numbers: ChaCha8 streams and distributions built only from bit operations,
//! IEEE arithmetic and the pure-Rust `libm`, so that a seed gives the same drive on every
//! platform (std's `ln`/`cos` call the platform's C library and may differ in the last bit).
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One independent random stream of a run.
#[derive(Debug, Clone)]
pub struct SimRng {
    rng: ChaCha8Rng,
    spare_normal: Option<f64>,
}

/// The streams of a run: separate so that changing one component does not shift another.
#[derive(Debug, Clone, Copy)]
#[repr(u64)]
pub enum Stream {
    /// Variations of the scenario's commands.
    Commands = 1,
    /// Speed report (clock, noise).
    SpeedReport = 2,
    /// Steering report.
    SteerReport = 3,
    /// Pedal report.
    PedalReport = 4,
    /// GNSS receiver.
    Gnss = 5,
    /// Fault injection.
    Faults = 6,
}

impl SimRng {
    /// Stream `stream` of the run with seed `seed`.
    pub fn new(seed: u64, stream: Stream) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(stream as u64);
        Self {
            rng,
            spare_normal: None,
        }
    }

    /// Uniform in [0, 1), 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn uniform_in(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box-Muller with libm).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        // u1 in (0, 1]: ln never sees 0.
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        let radius = libm::sqrt(-2.0 * libm::log(u1));
        let angle = 2.0 * core::f64::consts::PI * u2;
        self.spare_normal = Some(radius * libm::sin(angle));
        radius * libm::cos(angle)
    }

    /// Exponential with the given mean.
    pub fn exponential(&mut self, mean: f64) -> f64 {
        -mean * libm::log(1.0 - self.uniform())
    }

    /// True with probability p.
    pub fn chance(&mut self, p: f64) -> bool {
        self.uniform() < p
    }
}
