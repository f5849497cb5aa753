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
use nalgebra::{SMatrix, SVector};

use super::{clamp, max};
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

/// The problem data of one solve. Stage `k` of the arrays: dynamics and input of step
/// `k -> k + 1`, and the state cost, box and rows of `x_{k+1}`.
#[derive(Clone, Debug)]
pub struct Problem<const NX: usize, const N: usize, const NR: usize> {
    /// `A_k`.
    pub a: [SMatrix<f32, NX, NX>; N],
    /// `B_k`.
    pub b: [SVector<f32, NX>; N],
    /// `c_k` (affine term of the dynamics).
    pub c: [SVector<f32, NX>; N],
    /// Diagonal of the state cost of `x_{k+1}` (>= 0).
    pub q_diag: [SVector<f32, NX>; N],
    /// Linear state cost of `x_{k+1}`.
    pub q_lin: [SVector<f32, NX>; N],
    /// Input cost `r` (> 0).
    pub r: f32,
    /// Linear input cost of `u_k`.
    pub r_lin: [f32; N],
    /// Input bounds of `u_k` (hard).
    pub u_lower: [f32; N],
    /// Input bounds of `u_k` (hard).
    pub u_upper: [f32; N],
    /// ADMM penalty of the input bounds.
    pub u_rho: f32,
    /// The state with a hard box.
    pub box_state: usize,
    /// Its bounds at `x_{k+1}`.
    pub box_lower: [f32; N],
    /// Its bounds at `x_{k+1}`.
    pub box_upper: [f32; N],
    /// ADMM penalty of the box.
    pub box_rho: f32,
    /// Rows on `x_{k+1}`.
    pub rows: [[Row; NR]; N],
}

impl<const NX: usize, const N: usize, const NR: usize> Problem<NX, N, NR> {
    /// A problem with zero dynamics and cost, no rows and unbounded inputs and box; the
    /// formulation fills it in place every tick.
    pub fn zeroed() -> Self {
        Self {
            a: [SMatrix::zeros(); N],
            b: [SVector::zeros(); N],
            c: [SVector::zeros(); N],
            q_diag: [SVector::zeros(); N],
            q_lin: [SVector::zeros(); N],
            r: 1.0,
            r_lin: [0.0; N],
            u_lower: [f32::NEG_INFINITY; N],
            u_upper: [f32::INFINITY; N],
            u_rho: 1.0,
            box_state: 0,
            box_lower: [f32::NEG_INFINITY; N],
            box_upper: [f32::INFINITY; N],
            box_rho: 1.0,
            rows: [[Row::INACTIVE; NR]; N],
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

/// Gains, iterates and duals: the solver's state, kept between solves for the warm start.
#[derive(Clone, Debug)]
pub struct Workspace<const NX: usize, const N: usize, const NR: usize> {
    /// Factor on every penalty (adapted; kept for the next solve).
    pub rho_scale: f32,
    /// Factorisations done in the last solve.
    pub factorisations: u16,
    /// Each row's penalty times `rho_scale` (0 for inactive rows), set by `factor`.
    rho: [[f32; NR]; N],
    /// Each soft row's `mu / rho` at the current scale (`+inf` for hard rows).
    reach: [[f32; NR]; N],
    /// Feedback gains `u_k = -K_k x_k - d_k`.
    k: [SVector<f32, NX>; N],
    /// `1 / (r + rho_u + B' P B)` per stage.
    inv_quu: [f32; N],
    /// `P_{k+1} c_k` per stage.
    pc: [SVector<f32, NX>; N],
    /// Feedforward terms.
    d: [f32; N],
    /// Planned states `x_1 .. x_N`.
    pub x: [SVector<f32, NX>; N],
    /// Planned inputs `u_0 .. u_{N-1}`.
    pub u: [f32; N],
    /// Row copies.
    pub z: [[f32; NR]; N],
    /// Scaled row duals.
    pub w: [[f32; NR]; N],
    /// Box copies.
    pub zb: [f32; N],
    /// Scaled box duals.
    pub wb: [f32; N],
    /// Input copies.
    pub zu: [f32; N],
    /// Scaled input duals.
    pub wu: [f32; N],
}

impl<const NX: usize, const N: usize, const NR: usize> Default for Workspace<NX, N, NR> {
    fn default() -> Self {
        Self {
            rho_scale: 1.0,
            factorisations: 0,
            rho: [[0.0; NR]; N],
            reach: [[f32::INFINITY; NR]; N],
            k: [SVector::zeros(); N],
            inv_quu: [0.0; N],
            pc: [SVector::zeros(); N],
            d: [0.0; N],
            x: [SVector::zeros(); N],
            u: [0.0; N],
            z: [[0.0; NR]; N],
            w: [[0.0; NR]; N],
            zb: [0.0; N],
            wb: [0.0; N],
            zu: [0.0; N],
            wu: [0.0; N],
        }
    }
}

/// Adds the rows' and the box's `rho c c'` to `m` (their share of the quadratic cost).
#[inline(always)]
fn add_stage_quadratic<const NX: usize, const NR: usize>(
    m: &mut SMatrix<f32, NX, NX>,
    rows: &[Row; NR],
    rho: &[f32; NR],
    box_state: usize,
    box_rho: f32,
) {
    let (mut aa, mut ab, mut bb) = (0.0f32, 0.0f32, 0.0f32);
    for (row, rho) in rows.iter().zip(rho) {
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
}

/// Linear state cost of a stage in the current iteration: `q_lin + sum rho c (w - z)`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn stage_linear_cost<const NX: usize, const NR: usize>(
    q_lin: &SVector<f32, NX>,
    rows: &[Row; NR],
    rho: &[f32; NR],
    z: &[f32; NR],
    w: &[f32; NR],
    box_state: usize,
    box_term: f32,
) -> SVector<f32, NX> {
    let (mut qa, mut qb) = (0.0f32, 0.0f32);
    for (((row, rho), z), w) in rows.iter().zip(rho).zip(z).zip(w) {
        let s = rho * (w - z);
        qa += row.a * s;
        qb += row.b * s;
    }
    let mut q = *q_lin;
    let mut it = q.iter_mut();
    if let Some(v) = it.next() {
        *v += qa;
    }
    if let Some(v) = it.next() {
        *v += qb;
    }
    if let Some(v) = q.get_mut(box_state) {
        *v += box_term;
    }
    q
}

impl<const NX: usize, const N: usize, const NR: usize> Workspace<NX, N, NR> {
    /// The Riccati recursion of the iterations' LQR problem (fixed within a solve): gains
    /// `K_k`, pivots and `P_{k+1} c_k`.
    pub fn factor(&mut self, p: &Problem<NX, N, NR>) -> Result<(), SolveError> {
        let scale = self.rho_scale;
        for ((rho, reach), rows) in self.rho.iter_mut().zip(self.reach.iter_mut()).zip(&p.rows) {
            for ((rho, reach), row) in rho.iter_mut().zip(reach.iter_mut()).zip(rows) {
                *rho = if row.active { row.rho * scale } else { 0.0 };
                *reach = if row.soft_weight < f32::INFINITY && *rho > 0.0 {
                    row.soft_weight / *rho
                } else {
                    f32::INFINITY
                };
            }
        }
        let box_rho = p.box_rho * scale;
        // P_N: terminal cost plus the rows' quadratic part.
        let mut pm = SMatrix::<f32, NX, NX>::zeros();
        if let (Some(qd), Some(rows), Some(rho)) = (p.q_diag.last(), p.rows.last(), self.rho.last())
        {
            pm = SMatrix::from_diagonal(qd);
            add_stage_quadratic(&mut pm, rows, rho, p.box_state, box_rho);
        }
        let stages =
            p.a.iter()
                .zip(&p.b)
                .zip(&p.c)
                .zip(self.k.iter_mut().zip(self.inv_quu.iter_mut()))
                .zip(self.pc.iter_mut())
                .enumerate()
                .rev();
        for (k, ((((a, b), c), (gain, inv_quu)), pc)) in stages {
            let pb = pm * b;
            let quu = p.r + p.u_rho * scale + b.dot(&pb);
            if !(quu.is_finite() && quu > 0.0) {
                return Err(SolveError::BadPivot);
            }
            let inv = 1.0 / quu;
            let pa = pm * a;
            // K = (B' P A) / quu, stored as a column.
            *gain = pa.tr_mul(b) * inv;
            *inv_quu = inv;
            *pc = pm * c;
            // P_k for the stage before (not needed for k = 0: x_0 is fixed).
            if let Some(prev) = k.checked_sub(1) {
                let mut next = a.tr_mul(&pa) - (*gain * gain.transpose()) * quu;
                if let (Some(qd), Some(rows), Some(rho)) =
                    (p.q_diag.get(prev), p.rows.get(prev), self.rho.get(prev))
                {
                    for (i, q) in qd.iter().enumerate() {
                        if let Some(v) = next.get_mut((i, i)) {
                            *v += q;
                        }
                    }
                    add_stage_quadratic(&mut next, rows, rho, p.box_state, box_rho);
                }
                // Symmetrise: rounding would otherwise let P drift from symmetry.
                pm = (next + next.transpose()) * 0.5;
            }
        }
        self.factorisations = self.factorisations.saturating_add(1);
        Ok(())
    }

    /// Initialises the copies and duals from nothing: copies at the bounds' clamp of 0, duals 0.
    /// Use [`Workspace::shift`] instead to warm-start from the previous solve.
    pub fn cold_start(&mut self, p: &Problem<NX, N, NR>) {
        for ((z, w), rows) in self.z.iter_mut().zip(self.w.iter_mut()).zip(&p.rows) {
            for ((z, w), row) in z.iter_mut().zip(w.iter_mut()).zip(rows) {
                *z = clamp(0.0, row.lower, row.upper);
                *w = 0.0;
            }
        }
        for (((zb, wb), lo), hi) in self
            .zb
            .iter_mut()
            .zip(self.wb.iter_mut())
            .zip(&p.box_lower)
            .zip(&p.box_upper)
        {
            *zb = clamp(0.0, *lo, *hi);
            *wb = 0.0;
        }
        for (((zu, wu), lo), hi) in self
            .zu
            .iter_mut()
            .zip(self.wu.iter_mut())
            .zip(&p.u_lower)
            .zip(&p.u_upper)
        {
            *zu = clamp(0.0, *lo, *hi);
            *wu = 0.0;
        }
        self.rho_scale = 1.0;
    }

    /// Warm start: moves every copy and dual `fraction` of a stage towards the future (the
    /// time between two solves over the stage length), by linear interpolation; the last stage
    /// keeps its value. `fraction` is clamped to [0, 1].
    pub fn shift(&mut self, fraction: f32) {
        let f = fraction.clamp(0.0, 1.0);
        shift_rows(&mut self.z, f);
        shift_rows(&mut self.w, f);
        for v in [
            &mut self.zb,
            &mut self.wb,
            &mut self.zu,
            &mut self.wu,
            &mut self.u,
        ] {
            shift_values(v, f);
        }
        let old = self.x;
        for (i, xi) in self.x.iter_mut().enumerate() {
            if let Some(next) = old.get(i + 1) {
                *xi += (next - *xi) * f;
            }
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
        for w in self.w.iter_mut().flatten() {
            *w *= inv;
        }
        for w in self.wb.iter_mut().chain(self.wu.iter_mut()) {
            *w *= inv;
        }
        self.rho_scale = new_scale;
        self.factor(p)
    }

    /// The affine part of the Riccati recursion for the current copies and duals.
    #[inline(always)]
    fn backward(&mut self, p: &Problem<NX, N, NR>) {
        let u_rho = p.u_rho * self.rho_scale;
        let box_rho = p.box_rho * self.rho_scale;
        let bs = p.box_state;
        let mut p_next = SVector::<f32, NX>::zeros();
        if let (Some(ql), Some(rows), Some(rho), Some(z), Some(w), Some(zb), Some(wb)) = (
            p.q_lin.last(),
            p.rows.last(),
            self.rho.last(),
            self.z.last(),
            self.w.last(),
            self.zb.last(),
            self.wb.last(),
        ) {
            p_next = stage_linear_cost(ql, rows, rho, z, w, bs, box_rho * (wb - zb));
        }
        let stages =
            p.a.iter()
                .zip(&p.b)
                .zip(self.k.iter().zip(&self.inv_quu).zip(&self.pc))
                .zip(p.r_lin.iter().zip(&self.zu).zip(&self.wu))
                .zip(self.d.iter_mut())
                .enumerate()
                .rev();
        for (k, ((((a, b), ((gain, inv_quu), pc)), ((r_lin, zu), wu)), d)) in stages {
            let bvec = pc + p_next;
            let qu = r_lin + u_rho * (wu - zu) + b.dot(&bvec);
            *d = qu * inv_quu;
            if let Some(prev) = k.checked_sub(1) {
                if let (Some(ql), Some(rows), Some(rho), Some(z), Some(w), Some(zb), Some(wb)) = (
                    p.q_lin.get(prev),
                    p.rows.get(prev),
                    self.rho.get(prev),
                    self.z.get(prev),
                    self.w.get(prev),
                    self.zb.get(prev),
                    self.wb.get(prev),
                ) {
                    p_next = stage_linear_cost(ql, rows, rho, z, w, bs, box_rho * (wb - zb))
                        + a.tr_mul(&bvec)
                        - gain * qu;
                }
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
        let beta = 1.0 - alpha;
        let mut x = *x0;
        let mut r = Residuals {
            primal: 0.0,
            dual: 0.0,
            value_scale: 0.0,
            multiplier_scale: 0.0,
        };
        let stages =
            p.a.iter()
                .zip(&p.b)
                .zip(&p.c)
                .zip(self.k.iter().zip(&self.d))
                .zip(p.u_lower.iter().zip(&p.u_upper))
                .zip(
                    self.u
                        .iter_mut()
                        .zip(self.zu.iter_mut())
                        .zip(self.wu.iter_mut()),
                )
                .zip(self.x.iter_mut())
                .zip(p.box_lower.iter().zip(&p.box_upper))
                .zip(self.zb.iter_mut().zip(self.wb.iter_mut()))
                .zip(p.rows.iter().zip(self.rho.iter().zip(&self.reach)))
                .zip(self.z.iter_mut().zip(self.w.iter_mut()));
        for (
            (
                (
                    (((((((a, b), c), (gain, d)), (lo, hi)), ((u, zu), wu)), xs), (blo, bhi)),
                    (zb, wb),
                ),
                (rows, (rho, reach)),
            ),
            (z, w),
        ) in stages
        {
            let uk = -gain.dot(&x) - d;
            *u = uk;
            // Input copy: the hard box.
            let relaxed = alpha * uk + beta * *zu;
            let zu_new = clamp(relaxed + *wu, *lo, *hi);
            *wu += relaxed - zu_new;
            if CHECK {
                r.add(uk, *zu, zu_new, *wu, u_rho);
            }
            *zu = zu_new;
            x = a * x + b * uk + c;
            *xs = x;
            // State box.
            let g = x.get(p.box_state).copied().unwrap_or(0.0);
            let relaxed = alpha * g + beta * *zb;
            let zb_new = clamp(relaxed + *wb, *blo, *bhi);
            *wb += relaxed - zb_new;
            if CHECK {
                r.add(g, *zb, zb_new, *wb, box_rho);
            }
            *zb = zb_new;
            // Rows on the plane.
            let (x0, x1) = plane(&x);
            for ((((row, rho), reach), z), w) in rows
                .iter()
                .zip(rho)
                .zip(reach)
                .zip(z.iter_mut())
                .zip(w.iter_mut())
            {
                if *rho == 0.0 {
                    continue;
                }
                let g = row.a * x0 + row.b * x1;
                let relaxed = alpha * g + beta * *z;
                let z_new = prox(relaxed + *w, row.lower, row.upper, *reach);
                *w += relaxed - z_new;
                if CHECK {
                    r.add(g, *z, z_new, *w, *rho);
                }
                *z = z_new;
            }
        }
        r
    }
}

/// Linear interpolation of each stage's values `f` of the way to the next stage's.
fn shift_rows<const NR: usize, const N: usize>(v: &mut [[f32; NR]; N], f: f32) {
    let old = *v;
    for (i, cur) in v.iter_mut().enumerate() {
        if let Some(next) = old.get(i + 1) {
            for (c, n) in cur.iter_mut().zip(next) {
                *c += (n - *c) * f;
            }
        }
    }
}

/// [`shift_rows`] for one value per stage.
fn shift_values<const N: usize>(v: &mut [f32; N], f: f32) {
    let old = *v;
    for (i, cur) in v.iter_mut().enumerate() {
        if let Some(next) = old.get(i + 1) {
            *cur += (next - *cur) * f;
        }
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
