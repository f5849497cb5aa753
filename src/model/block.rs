//! The runtime LTI blocks the node steps every 20 ms, in f32.
//!
//! [`SsBlock`] is the configuration: discrete `A (N x N)`, `B (N)`, `C (N)`, `D` and the input
//! [`DelayLine`], rounded to f32 once from the f64 ZOH discretization
//! ([`crate::model::zoh`]). [`SsBlockState`] is the state: `x` and the delay line contents.
//! One step is
//! ```text
//! u_d = u[k - delay_samples]
//! y[k] = C x[k] + D u_d
//! x[k+1] = A x[k] + B u_d
//! ```
//! i.e. `N^2 + 2N` multiplies for fixed `N` (no loops over runtime sizes, no heap).
//! [`MisoBlock`] sums `M` SISO blocks driven by `M` inputs: eq 7's
//! `dx/dt = h1 v_m + h2 x + h3 y + h4 phi` as four 2nd-order blocks (block-diagonal, 4 x 8
//! multiplies for A instead of the 64 of a dense 8 x 8).
//!
//! Only + - * on f32 run here, so results are bit-identical on x86-64 and Cortex-M4F.

use nalgebra::{SMatrix, SVector};

use crate::image::{Image, ImageError, ImageReader, ImageWriter};

use super::delay::{DelayLine, DelayLineState};
use super::tf::{ModelError, TransferFunction};
use super::zoh::{discretize, DiscreteStateSpace};

/// Default input-delay capacity of a block, samples: 64 x 20 ms = 1.28 s, three times eq 5's
/// 0.42 s (21 samples). Costs 256 bytes of state per block.
pub const DEFAULT_DELAY_CAP: usize = 64;

/// A, B, C, D, the delay, the equilibrium and the gain, as the f64 discretization rounded them.
impl<const N: usize, const DELAY_CAP: usize> Image for SsBlock<N, DELAY_CAP> {
    fn write(&self, w: &mut ImageWriter<'_>) {
        let Self {
            a,
            b,
            c,
            d,
            delay,
            x_eq_per_u,
            dc_gain,
        } = self;
        a.write(w);
        b.write(w);
        c.write(w);
        d.write(w);
        delay.delay_samples().write(w);
        x_eq_per_u.write(w);
        dc_gain.write(w);
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        let a = SMatrix::read(r)?;
        let b = SVector::read(r)?;
        let c = SVector::read(r)?;
        let d = f32::read(r)?;
        let delay = DelayLine::new(usize::read(r)?).map_err(|_| r.out_of_range())?;
        Ok(Self {
            a,
            b,
            c,
            d,
            delay,
            x_eq_per_u: Option::read(r)?,
            dc_gain: Option::read(r)?,
        })
    }
}

/// A discrete SISO LTI block of order `N` with an input delay of up to `DELAY_CAP` samples
/// (configuration; immutable once built).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SsBlock<const N: usize, const DELAY_CAP: usize = DEFAULT_DELAY_CAP> {
    a: SMatrix<f32, N, N>,
    b: SVector<f32, N>,
    /// Output row `C` (as a column vector).`C`, stored as a column (`y = c . x`).
    c: SVector<f32, N>,
    d: f32,
    delay: DelayLine<DELAY_CAP>,
    /// `x*` with `x* = A x* + B` (f64-solved, then rounded); `None` with a pole at z = 1.
    x_eq_per_u: Option<SVector<f32, N>>,
    /// `C x* + D`, the steady-state gain; `None` with a pole at z = 1.
    dc_gain: Option<f32>,
}

/// The mutable part of an [`SsBlock`]: the state vector and the input delay line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SsBlockState<const N: usize, const DELAY_CAP: usize = DEFAULT_DELAY_CAP> {
    /// State vector `x[k]` (controllable canonical coordinates).
    pub x: SVector<f32, N>,
    /// Inputs in flight through the delay.
    pub delay: DelayLineState<DELAY_CAP>,
}

/// [`SsBlock::forecast`]: a copy of the state vector stepped along the inputs in flight, then a
/// held input.
#[derive(Clone, Debug)]
pub struct Forecast<'a, const N: usize, const DELAY_CAP: usize> {
    block: &'a SsBlock<N, DELAY_CAP>,
    x: SVector<f32, N>,
    /// The inputs in flight not used yet, in order: two pieces of the delay ring.
    in_flight: [&'a [f32]; 2],
    u_hold: f32,
}

impl<const N: usize, const DELAY_CAP: usize> Forecast<'_, N, DELAY_CAP> {
    /// The outputs of the next `out.len()` steps (each as [`SsBlock::step`] would return it).
    /// Three plain loops: over each piece of the inputs in flight, then with the held input.
    pub fn fill(&mut self, out: &mut [f32]) {
        let b = self.block;
        let mut out = out;
        for piece in &mut self.in_flight {
            let n = piece.len().min(out.len());
            let (now, rest) = out.split_at_mut(n);
            let (inputs, later) = piece.split_at(n);
            for (y, u) in now.iter_mut().zip(inputs) {
                *y = b.c.dot(&self.x) + b.d * u;
                self.x = b.a * self.x + b.b * *u;
            }
            *piece = later;
            out = rest;
        }
        let du = b.d * self.u_hold;
        let bu = b.b * self.u_hold;
        for y in out {
            *y = b.c.dot(&self.x) + du;
            self.x = b.a * self.x + bu;
        }
    }
}

impl<const N: usize, const DELAY_CAP: usize> SsBlock<N, DELAY_CAP> {
    /// ZOH-discretizes `tf` at `ts_s` (f64) and rounds to f32.
    ///
    /// Errors: [`ModelError::OrderMismatch`] if `tf.order() != N`, the delay errors of
    /// [`crate::model::zoh::delay_samples`], [`ModelError::DelayTooLong`] beyond `DELAY_CAP`.
    pub fn from_tf(tf: &TransferFunction, ts_s: f64) -> Result<Self, ModelError> {
        if tf.order() != N {
            return Err(ModelError::OrderMismatch {
                expected: N,
                found: tf.order(),
            });
        }
        Self::from_discrete(&discretize(tf, ts_s)?)
    }

    /// Rounds an f64 discretization to f32. Errors as [`SsBlock::from_tf`].
    pub fn from_discrete(dss: &DiscreteStateSpace) -> Result<Self, ModelError> {
        if dss.n != N {
            return Err(ModelError::OrderMismatch {
                expected: N,
                found: dss.n,
            });
        }
        let delay = DelayLine::new(dss.delay_samples)?;
        let a = SMatrix::<f32, N, N>::from_fn(|i, j| {
            dss.ad
                .get(i)
                .and_then(|row| row.get(j))
                .map_or(0.0, |v| *v as f32)
        });
        let b = SVector::<f32, N>::from_fn(|i, _| dss.bd.get(i).map_or(0.0, |v| *v as f32));
        let c = SVector::<f32, N>::from_fn(|j, _| dss.cd.get(j).map_or(0.0, |v| *v as f32));
        let (x_eq_per_u, dc_gain) = match dss.equilibrium_per_unit_input() {
            Ok(x64) => {
                let gain: f64 = dss.dd + x64.iter().zip(&dss.cd).map(|(x, c)| x * c).sum::<f64>();
                let x = SVector::<f32, N>::from_fn(|i, _| x64.get(i).map_or(0.0, |v| *v as f32));
                (Some(x), Some(gain as f32))
            }
            Err(_) => (None, None),
        };
        Ok(Self {
            a,
            b,
            c,
            d: dss.dd as f32,
            delay,
            x_eq_per_u,
            dc_gain,
        })
    }

    /// A block that outputs 0 for any input (`A = 0, B = 0, C = 0, D = 0`, no delay).
    pub fn zeroed() -> Self {
        Self {
            a: SMatrix::zeros(),
            b: SVector::zeros(),
            c: SVector::zeros(),
            d: 0.0,
            delay: DelayLine::NONE,
            x_eq_per_u: Some(SVector::zeros()),
            dc_gain: Some(0.0),
        }
    }

    /// One 20 ms step (see the module doc): returns `y[k]` and advances the state to `k + 1`.
    #[inline]
    pub fn step(&self, state: &mut SsBlockState<N, DELAY_CAP>, u: f32) -> f32 {
        let u_d = self.delay.push(&mut state.delay, u);
        let y = self.c.dot(&state.x) + self.d * u_d;
        state.x = self.a * state.x + self.b * u_d;
        y
    }

    /// The block's outputs from `state` on, without touching it: the inputs already in its
    /// delay line first (they reach the model in the next `delay_samples` steps), then `u_hold`
    /// held. Each output of [`Forecast::fill`] is one [`SsBlock::step`], bit for bit, without
    /// the ring buffer's bookkeeping (the horizon predictor's speed profile).
    pub fn forecast<'a>(
        &'a self,
        state: &'a SsBlockState<N, DELAY_CAP>,
        u_hold: f32,
    ) -> Forecast<'a, N, DELAY_CAP> {
        let (first, then) = self.delay.in_flight(&state.delay);
        Forecast {
            block: self,
            x: state.x,
            in_flight: [first, then],
            u_hold,
        }
    }

    /// All-zero state (zero output history and zero inputs in flight).
    pub fn zero_state(&self) -> SsBlockState<N, DELAY_CAP> {
        SsBlockState {
            x: SVector::zeros(),
            delay: self.delay.state_primed(0.0),
        }
    }

    /// The equilibrium for a constant input `u`: `x = x* u`, the delay line full of `u`, so
    /// the block outputs `dc_gain() * u` from the first step.
    /// [`ModelError::NoEquilibrium`] with a pole at z = 1.
    pub fn steady_state_for(&self, u: f32) -> Result<SsBlockState<N, DELAY_CAP>, ModelError> {
        let x_eq = self.x_eq_per_u.ok_or(ModelError::NoEquilibrium)?;
        Ok(SsBlockState {
            x: x_eq * u,
            delay: self.delay.state_primed(u),
        })
    }

    /// The equilibrium whose output is `y` (e.g. eq 5 started at the measured speed): the
    /// input is `y / dc_gain()`. [`ModelError::NoEquilibrium`] if the gain is 0 or undefined.
    pub fn steady_state_for_output(
        &self,
        y: f32,
    ) -> Result<SsBlockState<N, DELAY_CAP>, ModelError> {
        match self.dc_gain {
            Some(g) if g != 0.0 => self.steady_state_for(y / g),
            _ => Err(ModelError::NoEquilibrium),
        }
    }

    /// Steady-state gain `C (I - A)^{-1} B + D` (computed in f64, rounded), `None` with a pole
    /// at z = 1.
    pub fn dc_gain(&self) -> Option<f32> {
        self.dc_gain
    }
    /// Discrete state matrix.
    pub fn a(&self) -> &SMatrix<f32, N, N> {
        &self.a
    }
    /// Discrete input vector.
    pub fn b(&self) -> &SVector<f32, N> {
        &self.b
    }
    /// Output row `C` (as a column vector).
    pub fn c(&self) -> &SVector<f32, N> {
        &self.c
    }
    /// Direct feedthrough.
    pub fn d(&self) -> f32 {
        self.d
    }
    /// Input delay configuration.
    pub fn delay(&self) -> &DelayLine<DELAY_CAP> {
        &self.delay
    }
}

impl<const N: usize, const M: usize, const DELAY_CAP: usize> Image for MisoBlock<N, M, DELAY_CAP> {
    fn write(&self, w: &mut ImageWriter<'_>) {
        for block in &self.blocks {
            block.write(w);
        }
    }
    fn read(r: &mut ImageReader<'_>) -> Result<Self, ImageError> {
        let mut blocks = [SsBlock::zeroed(); M];
        for block in blocks.iter_mut() {
            *block = SsBlock::read(r)?;
        }
        Ok(Self { blocks })
    }
}

/// `M` SISO blocks of order `N`, one per input, outputs summed: `y = sum_i h_i(u_i)` (eq 7).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MisoBlock<const N: usize, const M: usize, const DELAY_CAP: usize = DEFAULT_DELAY_CAP> {
    blocks: [SsBlock<N, DELAY_CAP>; M],
}

/// State of a [`MisoBlock`]: one [`SsBlockState`] per input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MisoBlockState<
    const N: usize,
    const M: usize,
    const DELAY_CAP: usize = DEFAULT_DELAY_CAP,
> {
    /// Per-input block states, in input order.
    pub blocks: [SsBlockState<N, DELAY_CAP>; M],
}

impl<const N: usize, const M: usize, const DELAY_CAP: usize> MisoBlock<N, M, DELAY_CAP> {
    /// Discretizes each `tfs[i]` (input `i`) at `ts_s`; errors as [`SsBlock::from_tf`].
    pub fn from_tfs(tfs: &[TransferFunction; M], ts_s: f64) -> Result<Self, ModelError> {
        let mut blocks = [SsBlock::zeroed(); M];
        for (block, tf) in blocks.iter_mut().zip(tfs) {
            *block = SsBlock::from_tf(tf, ts_s)?;
        }
        Ok(Self { blocks })
    }

    /// The blocks of each input, in input order.
    pub fn from_blocks(blocks: [SsBlock<N, DELAY_CAP>; M]) -> Self {
        Self { blocks }
    }

    /// The SISO block of each input.
    pub fn blocks(&self) -> &[SsBlock<N, DELAY_CAP>; M] {
        &self.blocks
    }

    /// One step: `y[k] = sum_i y_i[k]`, summed in input order.
    #[inline]
    pub fn step(&self, state: &mut MisoBlockState<N, M, DELAY_CAP>, u: &[f32; M]) -> f32 {
        let mut y = 0.0;
        for ((block, st), ui) in self.blocks.iter().zip(state.blocks.iter_mut()).zip(u) {
            y += block.step(st, *ui);
        }
        y
    }

    /// All-zero state.
    pub fn zero_state(&self) -> MisoBlockState<N, M, DELAY_CAP> {
        let mut blocks = [SsBlock::<N, DELAY_CAP>::zeroed().zero_state(); M];
        for (st, block) in blocks.iter_mut().zip(&self.blocks) {
            *st = block.zero_state();
        }
        MisoBlockState { blocks }
    }

    /// The equilibrium for constant inputs `u`; errors if any block has a pole at z = 1.
    pub fn steady_state_for(
        &self,
        u: &[f32; M],
    ) -> Result<MisoBlockState<N, M, DELAY_CAP>, ModelError> {
        let mut state = self.zero_state();
        for ((st, block), ui) in state.blocks.iter_mut().zip(&self.blocks).zip(u) {
            *st = block.steady_state_for(*ui)?;
        }
        Ok(state)
    }

    /// Sum of the blocks' DC gains weighted by `u`: the steady output for constant inputs.
    pub fn steady_output_for(&self, u: &[f32; M]) -> Option<f32> {
        let mut y = 0.0;
        for (block, ui) in self.blocks.iter().zip(u) {
            y += block.dc_gain()? * ui;
        }
        Some(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_block_by_hand() {
        // 2/(s + 1) at Ts = ln 2: Ad = 1/2, Bd = 1 - 1/2 = 1/2, C = 2, D = 0; delay 1 sample.
        let ts = core::f64::consts::LN_2;
        let tf = TransferFunction::new(&[2.0], &[1.0, 1.0], ts).unwrap();
        let block = SsBlock::<1, 4>::from_tf(&tf, ts).unwrap();
        let mut st = block.zero_state();
        let y: Vec<f32> = (0..4).map(|_| block.step(&mut st, 1.0)).collect();
        // u_d = 0, 1, 1, 1; x = 0, 0, 0.5, 0.75; y = 2x.
        let expect = [0.0, 0.0, 1.0, 1.5];
        for (a, b) in y.iter().zip(expect) {
            assert!((a - b).abs() < 1e-6, "{y:?}");
        }
        assert!((block.dc_gain().unwrap() - 2.0).abs() < 1e-6);
        let mut st = block.steady_state_for_output(3.0).unwrap();
        assert!((block.step(&mut st, 1.5) - 3.0).abs() < 1e-6);
    }

    #[test]
    fn zeroed_miso_outputs_zero() {
        let miso = MisoBlock::<2, 3, 0> {
            blocks: [SsBlock::zeroed(); 3],
        };
        let mut st = miso.zero_state();
        assert_eq!(miso.step(&mut st, &[1.0, -2.0, 3.0]), 0.0);
        assert_eq!(miso.steady_output_for(&[1.0, 1.0, 1.0]), Some(0.0));
    }
}
