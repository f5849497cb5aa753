//! A time-varying linear-quadratic MPC solver: ADMM whose primal step is one Riccati sweep.
//!
//! Problem (one input, `NX` states, horizon `N`, at most `NR` rows per stage):
//! ```text
//! minimise    sum_{k=1..N} ( 1/2 x_k' diag(qd_k) x_k + ql_k' x_k )
//!           + sum_{k=0..N-1} ( 1/2 r u_k^2 + rl_k u_k )
//!           + sum_{soft rows i} mu_i dist(g_i, [lo_i, hi_i])
//! subject to  x_{k+1} = A_k x_k + B_k u_k + c_k,   x_0 given
//!             u_lo_k <= u_k <= u_hi_k                             (hard)
//!             box_lo_k <= x_k[box_state] <= box_hi_k              (hard)
//!             lo_i <= g_i <= hi_i for hard rows,  g_i = a_i x_k[0] + b_i x_k[1]
//! ```
//! Rows read the first two states (the controller's lateral plane, `e_y` and `e_psi`: a body
//! point's lateral offset is `a e_y + b e_psi + const`), and one more state has a hard box (the
//! steering angle). Fixing the rows' states is what makes a row cost a handful of instructions
//! (measured in docs/mpc.md; the first version, with two free state indices per row, spent
//! three quarters of each iteration on the rows).
//!
//! Soft rows carry an exact (L1) penalty `mu dist(g, [lo, hi])`: with `mu` above the row's
//! Lagrange multiplier the solution is that of the hard constraint whenever one exists
//! (exact-penalty theorem), and when none exists the problem stays feasible and the solver
//! still converges, to the least-violating plan: a body that is already outside its corridor
//! steers back in instead of making the problem infeasible.
//!
//! ADMM (Boyd et al. 2011, sec. 3; the splitting of OSQP, Stellato et al. 2020, and of TinyMPC,
//! Nguyen et al. 2024): every row, the box and the input get a copy `z` and a scaled dual `w`.
//! One iteration
//! 1. minimises the cost plus `rho/2 ||g - z + w||^2` subject to the dynamics: an LQR problem
//!    whose quadratic part is fixed during a solve, so its Riccati gains are computed once per
//!    solve ([`Workspace::factor`], `2 NX^3` multiply-adds per stage) and each iteration only
//!    sweeps the affine terms backward and rolls the policy forward (`2 NX^2` per stage);
//! 2. sets `z` to the proximal point of the row's constraint (a clamp, or a clamp moved by at
//!    most `mu / rho` for soft rows) at the over-relaxed value `alpha g + (1 - alpha) z`;
//! 3. adds the residual to `w`.
//!
//! Every `rho_update_every` iterations the penalties are rebalanced (OSQP's adaptive rho) and
//! the gains recomputed. TinyMPC caches the infinite-horizon gains of one fixed model; here the
//! model changes with speed and path curvature from stage to stage and tick to tick, so the
//! finite-horizon recursion is recomputed every solve. The iteration count is capped by the
//! caller and so is the number of factorisations: the work is bounded by construction.
//!
//! Only + - * / and comparisons on f32, in source order: bit-identical on the host and the
//! Cortex-M4F.
use core::ptr::addr_of_mut;

use nalgebra::{SMatrix, SVector};

use super::{clamp, max};
use crate::in_place::fill;
use crate::math;

/// Range of the adaptive penalty factor.
const RHO_SCALE_MIN: f32 = 1e-3;
const RHO_SCALE_MAX: f32 = 1e3;

/// One constraint row on a stage's state: `g = a x[0] + b x[1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// Coefficient of `x[0]`.
    pub a: f32,
    /// Coefficient of `x[1]`.
    pub b: f32,
    /// Lower bound (may be `-inf`).
    pub lower: f32,
    /// Upper bound (may be `+inf`).
    pub upper: f32,
    /// ADMM penalty of this row; scales with 1 / (row unit)^2.
    pub rho: f32,
    /// Exact-penalty weight `mu` (cost per unit of violation); `f32::INFINITY` = hard.
    pub soft_weight: f32,
    /// Inactive rows are skipped (no cost, no copy).
    pub active: bool,
}

impl Row {
    /// A row that does nothing.
    pub const INACTIVE: Row = Row {
        a: 0.0,
        b: 0.0,
        lower: f32::NEG_INFINITY,
        upper: f32::INFINITY,
        rho: 0.0,
        soft_weight: f32::INFINITY,
        active: false,
    };

    /// The row's value at `x`.
    #[inline(always)]
    pub fn eval<const NX: usize>(&self, x: &SVector<f32, NX>) -> f32 {
        let (x0, x1) = plane(x);
        self.a * x0 + self.b * x1
    }

    /// How far `g` lies outside the row's bounds (0 inside).
    #[inline]
    pub fn violation(&self, g: f32) -> f32 {
        max(max(g - self.upper, self.lower - g), 0.0)
    }
}

/// The first two states (0 if the state has fewer).
#[inline(always)]
fn plane<const NX: usize>(x: &SVector<f32, NX>) -> (f32, f32) {
    let mut it = x.iter();
    let x0 = it.next().copied().unwrap_or(0.0);
    let x1 = it.next().copied().unwrap_or(0.0);
    (x0, x1)
}

/// The proximal point of `mu dist(z, [lo, hi]) + rho/2 (z - v)^2` with `reach = mu / rho`:
/// the clamp `p` of `v`, plus what the violation `v - p` exceeds `reach` by. Exactly `p` for a
/// hard row (`reach = inf`).
#[inline(always)]
fn prox(v: f32, lo: f32, hi: f32, reach: f32) -> f32 {
    let p = clamp(v, lo, hi);
    let d = v - p;
    p + (d - clamp(d, -reach, reach))
}

/// One stage of the problem: the dynamics and input of step `k -> k + 1`, and the state cost,
/// box and rows of `x_{k+1}`.
#[derive(Clone, Copy, Debug)]
pub struct Stage<const NX: usize, const NR: usize> {
    /// `A_k`.
    pub a: SMatrix<f32, NX, NX>,
    /// `B_k`.
    pub b: SVector<f32, NX>,
    /// `c_k` (affine term of the dynamics).
    pub c: SVector<f32, NX>,
    /// Diagonal of the state cost of `x_{k+1}` (>= 0).
    pub q_diag: SVector<f32, NX>,
    /// Linear state cost of `x_{k+1}`.
    pub q_lin: SVector<f32, NX>,
    /// Linear input cost of `u_k`.
    pub r_lin: f32,
    /// Bounds of `u_k` (hard).
    pub u_lower: f32,
    /// Bounds of `u_k` (hard).
    pub u_upper: f32,
    /// Bounds of the boxed state of `x_{k+1}` (hard).
    pub box_lower: f32,
    /// Bounds of the boxed state of `x_{k+1}` (hard).
    pub box_upper: f32,
    /// Rows on `x_{k+1}`.
    pub rows: [Row; NR],
}

impl<const NX: usize, const NR: usize> Stage<NX, NR> {
    /// Zero dynamics and cost, no rows, no bounds.
    pub const ZERO: Self = Self {
        a: SMatrix::from_array_storage(nalgebra::ArrayStorage([[0.0; NX]; NX])),
        b: SVector::from_array_storage(nalgebra::ArrayStorage([[0.0; NX]; 1])),
        c: SVector::from_array_storage(nalgebra::ArrayStorage([[0.0; NX]; 1])),
        q_diag: SVector::from_array_storage(nalgebra::ArrayStorage([[0.0; NX]; 1])),
        q_lin: SVector::from_array_storage(nalgebra::ArrayStorage([[0.0; NX]; 1])),
        r_lin: 0.0,
        u_lower: f32::NEG_INFINITY,
        u_upper: f32::INFINITY,
        box_lower: f32::NEG_INFINITY,
        box_upper: f32::INFINITY,
        rows: [Row::INACTIVE; NR],
    };
}

/// Steps 2 and 3 of an iteration for one copy: `z` to the proximal point at the over-relaxed
/// `alpha g + (1 - alpha) z` (`bounds` = lower, upper, reach; a plain clamp unless `SOFT`), the
/// residual into `w`; with `CHECK`, the residuals into `r`.
#[inline(always)]
fn update_copy<const CHECK: bool, const SOFT: bool>(
    g: f32,
    z: &mut f32,
    w: &mut f32,
    (lo, hi, reach): (f32, f32, f32),
    (alpha, rho): (f32, f32),
    r: &mut Residuals,
) {
    let relaxed = alpha * g + (1.0 - alpha) * *z;
    let z_new = if SOFT {
        prox(relaxed + *w, lo, hi, reach)
    } else {
        clamp(relaxed + *w, lo, hi)
    };
    *w += relaxed - z_new;
    if CHECK {
        r.add(g, *z, z_new, *w, rho);
    }
    *z = z_new;
}

/// The problem data of one solve.
#[derive(Clone, Debug)]
pub struct Problem<const NX: usize, const N: usize, const NR: usize> {
    /// The stages, in time order.
    pub stages: [Stage<NX, NR>; N],
    /// Input cost `r` (> 0).
    pub r: f32,
    /// ADMM penalty of the input bounds.
    pub u_rho: f32,
    /// The state with a hard box.
    pub box_state: usize,
    /// ADMM penalty of the box.
    pub box_rho: f32,
}

impl<const NX: usize, const N: usize, const NR: usize> Problem<NX, N, NR> {
    /// A problem with zero dynamics and cost, no rows and unbounded inputs and box; the
    /// formulation fills it in place every tick. `const`, so that it can initialise a static.
    pub const fn zeroed() -> Self {
        Self {
            stages: [Stage::ZERO; N],
            r: 1.0,
            u_rho: 1.0,
            box_state: 0,
            box_rho: 1.0,
        }
    }

    /// Writes [`Problem::zeroed`] into `slot` in place (`crate::in_place`).
    ///
    /// # Safety
    ///
    /// `slot` must be valid for writes of a `Problem` and aligned for it.
    pub(crate) unsafe fn init_in_place(slot: *mut Self) {
        // SAFETY: every field of the `Problem` the caller vouches for, once each.
        unsafe {
            fill(addr_of_mut!((*slot).stages), Stage::ZERO);
            addr_of_mut!((*slot).r).write(1.0);
            addr_of_mut!((*slot).u_rho).write(1.0);
            addr_of_mut!((*slot).box_state).write(0);
            addr_of_mut!((*slot).box_rho).write(1.0);
        }
    }
}

/// Why a solve could not produce a plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SolveError {
    /// A Riccati pivot `r + B' P B` was not positive and finite (bad problem data).
    BadPivot,
    /// An iterate became non-finite (bad problem data).
    NonFinite,
}

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AdmmSettings {
    /// Iterations at most per solve (the bound of the worst case).
    pub max_iterations: u16,
    /// Stop early once the primal residual (max |g - z|, row units) is below this ...
    pub primal_tolerance: f32,
    /// ... and the dual residual (max rho |z - z_prev|) below this.
    pub dual_tolerance: f32,
    /// Over-relaxation alpha in (0, 2); 1.6 is the usual choice (Boyd et al. sec. 3.4.3).
    pub relaxation: f32,
    /// Residuals are computed (for the early exit) every this many iterations and at the last
    /// one; computing them costs about a third of an iteration. 0 is taken as 1.
    pub check_every: u16,
    /// Every this many iterations the penalties are rebalanced (OSQP's adaptive rho) and the
    /// Riccati recursion recomputed, if the residuals are out of balance by more than 5x;
    /// 0 = never. The worst case is `(max_iterations - 1) / rho_update_every` extra
    /// factorisations.
    pub rho_update_every: u16,
}

/// What a solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SolveReport {
    /// Iterations run.
    pub iterations: u16,
    /// Max |g - z| over all rows, the box and the inputs at the last check.
    pub primal_residual: f32,
    /// Max rho |z - z_prev| over the same at the last check.
    pub dual_residual: f32,
}

/// Residuals of one iteration and the scales they are judged against.
struct Residuals {
    /// Max |g - z|.
    primal: f32,
    /// Max rho |z - z_prev|.
    dual: f32,
    /// Max |g|.
    value_scale: f32,
    /// Max |rho w| (the multipliers).
    multiplier_scale: f32,
}

impl Residuals {
    /// One copy's contribution.
    #[inline(always)]
    fn add(&mut self, g: f32, z_old: f32, z_new: f32, w: f32, rho: f32) {
        self.dual = max(self.dual, rho * (z_new - z_old).abs());
        self.primal = max(self.primal, (g - z_new).abs());
        self.value_scale = max(self.value_scale, g.abs());
        self.multiplier_scale = max(self.multiplier_scale, rho * w.abs());
    }
}

/// The solver's per-stage quantities.
#[derive(Clone, Copy, Debug)]
pub struct StageIterate<const NX: usize, const NR: usize> {
    /// Feedback gain: `u_k = -K_k x_k - d_k`.
    k: SVector<f32, NX>,
    /// `1 / (r + rho_u + B' P B)`.
    inv_quu: f32,
    /// `P_{k+1} c_k`.
    pc: SVector<f32, NX>,
    /// Feedforward term.
    d: f32,
    /// Each row's penalty times the scale (0 for inactive rows), set by `factor`.
    rho: [f32; NR],
    /// Each soft row's `mu / rho` at the current scale (`+inf` for hard rows).
    reach: [f32; NR],
    /// Planned state `x_{k+1}`.
    pub x: SVector<f32, NX>,
    /// Planned input `u_k`.
    pub u: f32,
    /// Row copies.
    pub z: [f32; NR],
    /// Scaled row duals.
    pub w: [f32; NR],
    /// Box copy.
    pub zb: f32,
    /// Scaled box dual.
    pub wb: f32,
    /// Input copy.
    pub zu: f32,
    /// Scaled input dual.
    pub wu: f32,
}

impl<const NX: usize, const NR: usize> StageIterate<NX, NR> {
    const ZERO: Self = Self {
        k: SVector::from_array_storage(nalgebra::ArrayStorage([[0.0; NX]; 1])),
        inv_quu: 0.0,
        pc: SVector::from_array_storage(nalgebra::ArrayStorage([[0.0; NX]; 1])),
        d: 0.0,
        rho: [0.0; NR],
        reach: [f32::INFINITY; NR],
        x: SVector::from_array_storage(nalgebra::ArrayStorage([[0.0; NX]; 1])),
        u: 0.0,
        z: [0.0; NR],
        w: [0.0; NR],
        zb: 0.0,
        wb: 0.0,
        zu: 0.0,
        wu: 0.0,
    };

    /// This stage's values moved `f` of the way towards `next`'s (gains untouched).
    fn lerp_towards(&mut self, next: &Self, f: f32) {
        let mix = |a: &mut f32, b: f32| *a += (b - *a) * f;
        for (a, b) in self.z.iter_mut().zip(&next.z) {
            mix(a, *b);
        }
        for (a, b) in self.w.iter_mut().zip(&next.w) {
            mix(a, *b);
        }
        mix(&mut self.zb, next.zb);
        mix(&mut self.wb, next.wb);
        mix(&mut self.zu, next.zu);
        mix(&mut self.wu, next.wu);
        mix(&mut self.u, next.u);
        self.x += (next.x - self.x) * f;
    }
}

/// Gains, iterates and duals: the solver's state, kept between solves for the warm start.
#[derive(Clone, Debug)]
pub struct Workspace<const NX: usize, const N: usize, const NR: usize> {
    /// Factor on every penalty (adapted; kept for the next solve).
    pub rho_scale: f32,
    /// Factorisations done in the last solve.
    pub factorisations: u16,
    /// Per stage.
    pub stages: [StageIterate<NX, NR>; N],
}

impl<const NX: usize, const N: usize, const NR: usize> Workspace<NX, N, NR> {
    /// Nothing solved yet. `const`, so that it can initialise a static.
    pub const fn new() -> Self {
        Self {
            rho_scale: 1.0,
            factorisations: 0,
            stages: [StageIterate::ZERO; N],
        }
    }

    /// Writes [`Workspace::new`] into `slot` in place (`crate::in_place`).
    ///
    /// # Safety
    ///
    /// `slot` must be valid for writes of a `Workspace` and aligned for it.
    pub(crate) unsafe fn init_in_place(slot: *mut Self) {
        // SAFETY: every field of the `Workspace` the caller vouches for, once each.
        unsafe {
            addr_of_mut!((*slot).rho_scale).write(1.0);
            addr_of_mut!((*slot).factorisations).write(0);
            fill(addr_of_mut!((*slot).stages), StageIterate::ZERO);
        }
    }
}

impl<const NX: usize, const N: usize, const NR: usize> Default for Workspace<NX, N, NR> {
    fn default() -> Self {
        Self::new()
    }
}

/// The state cost of a stage's `x_{k+1}` in the iterations' LQR problem: its diagonal plus the
/// rows' and the box's `rho c c'`.
#[inline(always)]
fn stage_quadratic<const NX: usize, const NR: usize>(
    st: &Stage<NX, NR>,
    it: &StageIterate<NX, NR>,
    box_state: usize,
    box_rho: f32,
) -> SMatrix<f32, NX, NX> {
    let mut m = SMatrix::<f32, NX, NX>::from_diagonal(&st.q_diag);
    let (mut aa, mut ab, mut bb) = (0.0f32, 0.0f32, 0.0f32);
    for (row, rho) in st.rows.iter().zip(&it.rho) {
        aa += rho * row.a * row.a;
        ab += rho * row.a * row.b;
        bb += rho * row.b * row.b;
    }
    for (ij, v) in [((0, 0), aa), ((0, 1), ab), ((1, 0), ab), ((1, 1), bb)] {
        if let Some(x) = m.get_mut(ij) {
            *x += v;
        }
    }
    if let Some(x) = m.get_mut((box_state, box_state)) {
        *x += box_rho;
    }
    m
}

impl<const NX: usize, const N: usize, const NR: usize> Workspace<NX, N, NR> {
    /// The Riccati recursion of the iterations' LQR problem (fixed within a solve): gains
    /// `K_k`, pivots and `P_{k+1} c_k`.
    pub fn factor(&mut self, p: &Problem<NX, N, NR>) -> Result<(), SolveError> {
        let scale = self.rho_scale;
        let box_rho = p.box_rho * scale;
        let u_rho = p.u_rho * scale;
        // P_{k+1} while sweeping back: starts as the terminal cost.
        let mut pm = SMatrix::<f32, NX, NX>::zeros();
        for (st, it) in p.stages.iter().zip(self.stages.iter_mut()).rev() {
            let (x0, x1) = plane(&it.x);
            for ((((rho, reach), row), z), w) in it
                .rho
                .iter_mut()
                .zip(it.reach.iter_mut())
                .zip(&st.rows)
                .zip(it.z.iter_mut())
                .zip(it.w.iter_mut())
            {
                let was_active = *rho != 0.0;
                *rho = if row.active { row.rho * scale } else { 0.0 };
                if row.active && !was_active {
                    // A row that joins (an obstacle coming into reach): its copy starts at the
                    // previous plan's value clamped, its dual at 0.
                    *z = clamp(row.a * x0 + row.b * x1, row.lower, row.upper);
                    *w = 0.0;
                }
                *reach = if row.soft_weight < f32::INFINITY && *rho > 0.0 {
                    row.soft_weight / *rho
                } else {
                    f32::INFINITY
                };
            }
            // The cost of x_{k+1} joins P_{k+1}.
            pm += stage_quadratic(st, it, p.box_state, box_rho);
            let pb = pm * st.b;
            let quu = p.r + u_rho + st.b.dot(&pb);
            if !(quu.is_finite() && quu > 0.0) {
                return Err(SolveError::BadPivot);
            }
            let inv = 1.0 / quu;
            let pa = pm * st.a;
            // K = (B' P A) / quu.
            it.k = pa.tr_mul(&st.b) * inv;
            it.inv_quu = inv;
            it.pc = pm * st.c;
            // P_k without x_k's own cost (added when the previous stage is reached).
            let next = st.a.tr_mul(&pa) - (it.k * it.k.transpose()) * quu;
            // Symmetrise: rounding would otherwise let P drift from symmetry.
            pm = (next + next.transpose()) * 0.5;
        }
        self.factorisations = self.factorisations.saturating_add(1);
        Ok(())
    }

    /// For a workspace whose next solve cold-starts ([`Workspace::cold_start`]): the next solve
    /// is then exactly the one after [`Workspace::reset`], for about a tenth of its cost (4 400
    /// instructions on the MCU, `cargo qemu`, in every tick that loads a path, up to three
    /// times). Of what a solve keeps, the factorisation reads each stage's penalties (which
    /// rows were active) and planned state before it writes them: a row that joins has its
    /// copy started at the planned state, clamped. With the planned states back to zero that
    /// start is the cold start's own, clamped 0, whichever rows were active, so the penalties
    /// may stay. The copies and duals are the cold start's; the gains, penalties and reaches
    /// the factorisation's; the inputs and states the iterations'. A warm start
    /// ([`Workspace::shift`]) after it would move stale values: the caller cold-starts next
    /// (the controller's `lin` is `None`).
    #[inline(never)]
    pub fn forget(&mut self) {
        self.rho_scale = 1.0;
        self.factorisations = 0;
        for it in self.stages.iter_mut() {
            it.x = SVector::zeros();
        }
    }

    /// Back to the state of `Workspace::default()`, in place (no 3.5 KiB temporary on the
    /// stack).
    pub fn reset(&mut self) {
        self.rho_scale = 1.0;
        self.factorisations = 0;
        for it in self.stages.iter_mut() {
            *it = StageIterate::ZERO;
        }
    }

    /// Initialises the copies and duals from nothing: copies at the bounds' clamp of 0, duals 0.
    /// Use [`Workspace::shift`] instead to warm-start from the previous solve.
    pub fn cold_start(&mut self, p: &Problem<NX, N, NR>) {
        for (st, it) in p.stages.iter().zip(self.stages.iter_mut()) {
            for ((z, w), row) in it.z.iter_mut().zip(it.w.iter_mut()).zip(&st.rows) {
                *z = clamp(0.0, row.lower, row.upper);
                *w = 0.0;
            }
            it.zb = clamp(0.0, st.box_lower, st.box_upper);
            it.wb = 0.0;
            it.zu = clamp(0.0, st.u_lower, st.u_upper);
            it.wu = 0.0;
        }
        self.rho_scale = 1.0;
    }

    /// Warm start: moves every copy, dual and iterate `fraction` of a stage towards the future
    /// (the time between two solves over the stage length), by linear interpolation; the last
    /// stage keeps its value. `fraction` is clamped to [0, 1].
    pub fn shift(&mut self, fraction: f32) {
        self.shift_each(&[fraction; N]);
    }

    /// [`Workspace::shift`] with a fraction per stage (stages of different lengths).
    pub fn shift_each(&mut self, fractions: &[f32; N]) {
        // In time order, each stage towards its successor's old value (not yet moved).
        let mut rest = self.stages.as_mut_slice();
        let mut f = fractions.iter();
        while let (Some((it, tail)), Some(f)) = (rest.split_first_mut(), f.next()) {
            if let Some(next) = tail.first() {
                it.lerp_towards(next, f.clamp(0.0, 1.0));
            }
            rest = tail;
        }
    }

    /// Runs ADMM from the current copies and duals (after [`Workspace::factor`]) from `x0`.
    pub fn iterate(
        &mut self,
        p: &Problem<NX, N, NR>,
        x0: &SVector<f32, NX>,
        settings: &AdmmSettings,
    ) -> Result<SolveReport, SolveError> {
        let alpha = settings.relaxation;
        let check_every = settings.check_every.max(1);
        let mut report = SolveReport::default();
        for i in 1..=settings.max_iterations {
            self.backward(p);
            let rebalance = settings.rho_update_every > 0
                && i % settings.rho_update_every == 0
                && i < settings.max_iterations;
            report.iterations = i;
            if !(rebalance || i % check_every == 0 || i == settings.max_iterations) {
                self.forward::<false>(p, x0, alpha);
                continue;
            }
            let r = self.forward::<true>(p, x0, alpha);
            report.primal_residual = r.primal;
            report.dual_residual = r.dual;
            if !(r.primal.is_finite() && r.dual.is_finite()) {
                return Err(SolveError::NonFinite);
            }
            if r.primal <= settings.primal_tolerance && r.dual <= settings.dual_tolerance {
                break;
            }
            if rebalance {
                self.rebalance(p, &r)?;
            }
        }
        Ok(report)
    }

    /// OSQP's penalty update (Stellato et al. 2020, sec. 5.2): scale every penalty by
    /// `sqrt(relative primal / relative dual residual)` when that is beyond 5x either way, keep
    /// the multipliers (`y = rho w`, so `w` is divided by the factor) and refactor.
    fn rebalance(&mut self, p: &Problem<NX, N, NR>, r: &Residuals) -> Result<(), SolveError> {
        let rel_primal = r.primal / max(r.value_scale, 1e-6);
        let rel_dual = r.dual / max(r.multiplier_scale, 1e-6);
        if !(rel_primal > 0.0 && rel_dual > 0.0) {
            return Ok(());
        }
        let ratio = math::sqrt(rel_primal / rel_dual).clamp(1e-2, 1e2);
        if ratio < 5.0 && ratio > 0.2 {
            return Ok(());
        }
        let new_scale = (self.rho_scale * ratio).clamp(RHO_SCALE_MIN, RHO_SCALE_MAX);
        let factor = new_scale / self.rho_scale;
        if factor == 1.0 {
            return Ok(());
        }
        let inv = 1.0 / factor;
        for it in self.stages.iter_mut() {
            for w in it.w.iter_mut() {
                *w *= inv;
            }
            it.wb *= inv;
            it.wu *= inv;
        }
        self.rho_scale = new_scale;
        self.factor(p)
    }

    /// The affine part of the Riccati recursion for the current copies and duals.
    ///
    /// This and [`Workspace::forward`] are the solver's inner loops; they work on the column
    /// arrays of the nalgebra matrices with fixed-length loops that the compiler unrolls, so
    /// the vectors stay in registers (with nalgebra's operators every intermediate 5-vector
    /// went through the stack: measured 560 instructions per stage for the two sweeps, against
    /// a fraction of that here; docs/mpc.md).
    #[inline(always)]
    fn backward(&mut self, p: &Problem<NX, N, NR>) {
        let u_rho = p.u_rho * self.rho_scale;
        let box_rho = p.box_rho * self.rho_scale;
        // A_{k+1}' b_{k+1} - K_{k+1} qu_{k+1}: the part of p_{k+1} from the stages after.
        let mut carry = [0.0f32; NX];
        for (st, it) in p.stages.iter().zip(self.stages.iter_mut()).rev() {
            // p_{k+1} = the linear cost of x_{k+1} (rows, box) + carry; b = P c + p.
            let (mut qa, mut qb) = (0.0f32, 0.0f32);
            for (((row, rho), z), w) in st.rows.iter().zip(&it.rho).zip(&it.z).zip(&it.w) {
                let s = rho * (w - z);
                qa += row.a * s;
                qb += row.b * s;
            }
            let mut bvec = [0.0f32; NX];
            for (i, ((bv, (q, pc)), cr)) in bvec
                .iter_mut()
                .zip(st.q_lin.iter().zip(it.pc.iter()))
                .zip(&carry)
                .enumerate()
            {
                let extra = match i {
                    0 => qa,
                    1 => qb,
                    _ => 0.0,
                };
                *bv = q + extra + cr + pc;
            }
            if let Some(bv) = bvec.get_mut(p.box_state) {
                *bv += box_rho * (it.wb - it.zb);
            }
            let mut qu = st.r_lin + u_rho * (it.wu - it.zu);
            for (b, bv) in st.b.iter().zip(&bvec) {
                qu += b * bv;
            }
            it.d = qu * it.inv_quu;
            // carry = A' b - K qu: column j of A dotted with b.
            for ((c, col), k) in carry.iter_mut().zip(&st.a.data.0).zip(it.k.iter()) {
                let mut sum = 0.0f32;
                for (a, bv) in col.iter().zip(&bvec) {
                    sum += a * bv;
                }
                *c = sum - k * qu;
            }
        }
    }

    /// Rolls the policy forward from `x0` and updates copies and duals; with `CHECK`, also
    /// returns the residuals and their scales (else zeros).
    #[inline(always)]
    fn forward<const CHECK: bool>(
        &mut self,
        p: &Problem<NX, N, NR>,
        x0: &SVector<f32, NX>,
        alpha: f32,
    ) -> Residuals {
        let u_rho = p.u_rho * self.rho_scale;
        let box_rho = p.box_rho * self.rho_scale;
        let mut x = x0.data.0[0];
        let mut r = Residuals {
            primal: 0.0,
            dual: 0.0,
            value_scale: 0.0,
            multiplier_scale: 0.0,
        };
        for (st, it) in p.stages.iter().zip(self.stages.iter_mut()) {
            let mut uk = -it.d;
            for (k, xi) in it.k.iter().zip(&x) {
                uk -= k * xi;
            }
            it.u = uk;
            // Input copy: the hard box.
            let box_u = (st.u_lower, st.u_upper, f32::INFINITY);
            update_copy::<CHECK, false>(uk, &mut it.zu, &mut it.wu, box_u, (alpha, u_rho), &mut r);
            // x_{k+1} = A x + B u + c, column by column.
            let mut xn = [0.0f32; NX];
            for ((xn, b), c) in xn.iter_mut().zip(st.b.iter()).zip(st.c.iter()) {
                *xn = b * uk + c;
            }
            for (col, xj) in st.a.data.0.iter().zip(&x) {
                for (xn, a) in xn.iter_mut().zip(col) {
                    *xn += a * xj;
                }
            }
            x = xn;
            it.x = SVector::from(xn);
            // State box.
            let g = x.get(p.box_state).copied().unwrap_or(0.0);
            let box_x = (st.box_lower, st.box_upper, f32::INFINITY);
            update_copy::<CHECK, false>(g, &mut it.zb, &mut it.wb, box_x, (alpha, box_rho), &mut r);
            // Rows on the plane.
            let mut first = x.iter();
            let x0 = first.next().copied().unwrap_or(0.0);
            let x1 = first.next().copied().unwrap_or(0.0);
            for ((((row, rho), reach), z), w) in st
                .rows
                .iter()
                .zip(&it.rho)
                .zip(&it.reach)
                .zip(it.z.iter_mut())
                .zip(it.w.iter_mut())
            {
                if *rho == 0.0 {
                    continue;
                }
                let g = row.a * x0 + row.b * x1;
                let bounds = (row.lower, row.upper, *reach);
                update_copy::<CHECK, true>(g, z, w, bounds, (alpha, *rho), &mut r);
            }
        }
        r
    }
}

/// Factors and iterates: one complete solve from the workspace's current copies and duals.
pub fn solve<const NX: usize, const N: usize, const NR: usize>(
    ws: &mut Workspace<NX, N, NR>,
    p: &Problem<NX, N, NR>,
    x0: &SVector<f32, NX>,
    settings: &AdmmSettings,
) -> Result<SolveReport, SolveError> {
    ws.factorisations = 0;
    ws.factor(p)?;
    ws.iterate(p, x0, settings)
}
