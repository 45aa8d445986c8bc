//! Feedforward stiffness allocation (paper B §4.3, eq. 31; MODEL.md §4).
//!
//! ```text
//! min_k ½‖S·k − K_U^dsr‖²   subject to   k_min ≤ k ≤ k_max
//! ```
//!
//! solved by bounded-variable least squares (Stark & Parker's BVLS, an active-set method).
//! The achieved S·k of the optimum is unique; the joint stiffnesses need not be: with four
//! actuators and three targets the optima form a segment. Paper B takes whatever `lsqlin`
//! returns. We break the tie on purpose: among all optimal k, pick the one **closest to the
//! centre of each joint's range, measured in fractions of that range**,
//!
//! ```text
//! min Σ ((k_i − c_i)/w_i)²   s.t.  S·k = S·k*,  k_min ≤ k ≤ k_max,   c = (k_min+k_max)/2, w = k_max−k_min
//! ```
//!
//! which leaves every joint the most room to be stiffened or softened later, and is unique
//! (strictly convex). It is solved exactly by enumerating active sets (3ⁿ, n ≤ 4 here).
//!
//! **The fast path** (the parallel robot: 4 joints, S of rank 3, a target inside the box's
//! image). Then every optimum meets the target exactly and the optima are the segment
//! k_p + s·v inside the bounds, v the null direction of S (its signed 3×3 minors) and k_p any
//! exact solution: the tie-break is a quadratic in s, minimised in closed form and clamped to
//! the segment. [`AllocationProblem::solve`] takes it when it applies and falls back to BVLS
//! and the enumeration otherwise (an infeasible target, another shape); both give the same k
//! (tested on 10 000 random problems, and `cargo bench -p rig-model --bench model` times both).

use nalgebra::{DMatrix, DVector};
use thiserror::Error;

/// Errors of the allocation.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AllocationError {
    #[error("S has {rows} rows and {cols} columns; bounds have {bounds} entries, target {target}")]
    Dimension {
        rows: usize,
        cols: usize,
        bounds: usize,
        target: usize,
    },
    #[error("non-finite {0}")]
    NonFinite(&'static str),
    #[error("bounds of joint {joint} are inverted or negative: [{min}, {max}] N·m/rad")]
    Bounds { joint: usize, min: f64, max: f64 },
    #[error("the bounded least-squares solver did not converge in {0} iterations")]
    NoConvergence(usize),
    #[error("percentage {0} is outside [0, 100]")]
    Percent(f64),
}

/// Operational stiffness (k_xx, k_xy, k_yy) [N/m].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperationalStiffness {
    pub xx: f64,
    pub xy: f64,
    pub yy: f64,
}

impl OperationalStiffness {
    fn to_vector(self) -> DVector<f64> {
        DVector::from_vec(vec![self.xx, self.xy, self.yy])
    }

    fn from_vector(v: &DVector<f64>) -> Self {
        Self {
            xx: v[0],
            xy: v[1],
            yy: v[2],
        }
    }
}

/// The allocation problem at one pose.
#[derive(Debug, Clone, PartialEq)]
pub struct AllocationProblem {
    /// S (3 × n).
    pub s: DMatrix<f64>,
    /// Lower joint-stiffness bounds [N·m/rad].
    pub k_min: DVector<f64>,
    /// Upper joint-stiffness bounds [N·m/rad].
    pub k_max: DVector<f64>,
}

/// The result of an allocation.
#[derive(Debug, Clone, PartialEq)]
pub struct Allocation {
    /// Joint stiffnesses [N·m/rad].
    pub k: DVector<f64>,
    /// The operational stiffness they give, S·k.
    pub achieved: OperationalStiffness,
    /// The target.
    pub target: OperationalStiffness,
    /// ‖S·k − target‖ [N/m].
    pub residual: f64,
    /// Whether the target is met (residual within tolerance).
    pub feasible: bool,
    /// Joints at a bound (−1 at k_min, +1 at k_max, 0 free).
    pub at_bound: Vec<i8>,
    /// Dimension of the set of optimal k before the tie-break (0: unique).
    pub optimal_set_dim: usize,
}

/// The operational range, as paper B defines it: (S·k_min, S·k_max).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperationalRange {
    pub min: OperationalStiffness,
    pub max: OperationalStiffness,
}

impl AllocationProblem {
    /// A problem with the given S and bounds; checks shapes, finiteness and bound order.
    pub fn new(
        s: DMatrix<f64>,
        k_min: DVector<f64>,
        k_max: DVector<f64>,
    ) -> Result<Self, AllocationError> {
        if s.nrows() != 3 || k_min.len() != s.ncols() || k_max.len() != s.ncols() {
            return Err(AllocationError::Dimension {
                rows: s.nrows(),
                cols: s.ncols(),
                bounds: k_min.len(),
                target: 3,
            });
        }
        if s.iter().any(|v| !v.is_finite()) {
            return Err(AllocationError::NonFinite("S matrix"));
        }
        for j in 0..k_min.len() {
            let (lo, hi) = (k_min[j], k_max[j]);
            if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo <= hi) {
                return Err(AllocationError::Bounds {
                    joint: j,
                    min: lo,
                    max: hi,
                });
            }
        }
        Ok(Self { s, k_min, k_max })
    }

    /// Paper B's range: S·k_min and S·k_max (0 % and 100 %).
    pub fn range(&self) -> OperationalRange {
        OperationalRange {
            min: OperationalStiffness::from_vector(&(&self.s * &self.k_min)),
            max: OperationalStiffness::from_vector(&(&self.s * &self.k_max)),
        }
    }

    /// The true extent of each component over the box of joint stiffnesses
    /// (min and max of each row of S·k, which may differ from [`Self::range`]).
    pub fn extent(&self) -> OperationalRange {
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for r in 0..3 {
            for j in 0..self.s.ncols() {
                let (a, b) = (
                    self.s[(r, j)] * self.k_min[j],
                    self.s[(r, j)] * self.k_max[j],
                );
                lo[r] += a.min(b);
                hi[r] += a.max(b);
            }
        }
        OperationalRange {
            min: OperationalStiffness {
                xx: lo[0],
                xy: lo[1],
                yy: lo[2],
            },
            max: OperationalStiffness {
                xx: hi[0],
                xy: hi[1],
                yy: hi[2],
            },
        }
    }

    /// Paper B's decoupled target: k_xx, k_yy at `percent` of the range, k_xy = 0.
    pub fn decoupled_target(&self, percent: f64) -> Result<OperationalStiffness, AllocationError> {
        if !(0.0..=100.0).contains(&percent) {
            return Err(AllocationError::Percent(percent));
        }
        let r = self.range();
        let f = percent / 100.0;
        Ok(OperationalStiffness {
            xx: r.min.xx + f * (r.max.xx - r.min.xx),
            xy: 0.0,
            yy: r.min.yy + f * (r.max.yy - r.min.yy),
        })
    }

    /// Solves eq. 31 and breaks ties as the module explains: in closed form along the null
    /// space where it applies, else by [`Self::solve_by_active_sets`].
    pub fn solve(&self, target: OperationalStiffness) -> Result<Allocation, AllocationError> {
        let t = target.to_vector();
        if t.iter().any(|v| !v.is_finite()) {
            return Err(AllocationError::NonFinite("target stiffness"));
        }
        match self.solve_along_null_space(&t) {
            Some(k) => Ok(self.allocation(k, target, &t, 1)),
            None => self.solve_by_active_sets(target),
        }
    }

    /// The closed form of the module's fast path: four joints, S of rank 3, a target met
    /// exactly inside the bounds. None where it does not apply.
    fn solve_along_null_space(&self, t: &DVector<f64>) -> Option<DVector<f64>> {
        if self.s.ncols() != 4 {
            return None;
        }
        let s = nalgebra::Matrix3x4::from_fn(|r, c| self.s[(r, c)]);
        // v_j = (−1)^j·det(S without column j): S·v = 0 (Laplace expansion of a 4×4 matrix
        // with a repeated row).
        let minor = |j: usize| {
            let cols: Vec<usize> = (0..4).filter(|&c| c != j).collect();
            nalgebra::Matrix3::from_fn(|r, c| s[(r, cols[c])]).determinant()
        };
        let v = nalgebra::Vector4::from_fn(|j, _| if j % 2 == 0 { minor(j) } else { -minor(j) });
        // Rank 3 (as the enumeration's SVD rank decides it): the largest minor is not lost in
        // rounding.
        let scale = s.abs().max().max(1e-300);
        let drop = v.iamax();
        if v[drop].abs() <= 1e-12 * scale.powi(3) {
            return None;
        }
        // An exact solution with the joint of the largest minor at 0: the best-conditioned
        // 3×3 system.
        let cols: Vec<usize> = (0..4).filter(|&c| c != drop).collect();
        let sq = nalgebra::Matrix3::from_fn(|r, c| s[(r, cols[c])]);
        let z = sq.lu().solve(&nalgebra::Vector3::new(t[0], t[1], t[2]))?;
        let mut kp = nalgebra::Vector4::zeros();
        for (i, &c) in cols.iter().enumerate() {
            kp[c] = z[i];
        }
        // The segment of k_p + σ·v inside the bounds.
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for j in 0..4 {
            if v[j] == 0.0 {
                // This joint does not move along the segment: it must already be inside.
                if kp[j] < self.k_min[j] || kp[j] > self.k_max[j] {
                    return None;
                }
                continue;
            }
            let (a, b) = (
                (self.k_min[j] - kp[j]) / v[j],
                (self.k_max[j] - kp[j]) / v[j],
            );
            lo = lo.max(a.min(b));
            hi = hi.min(a.max(b));
        }
        // Empty (beyond rounding): the target is not met inside the box; BVLS finds the
        // nearest one.
        let tol = 1e-12 * (hi.abs().max(lo.abs()).max(1e-300));
        if lo.is_nan() || hi.is_nan() || lo > hi + tol {
            return None;
        }
        // Σ ((k_p + σ·v − c)/w)² is least at σ₀ = Σ v(c − k_p)/w² / Σ v²/w².
        let (mut num, mut den) = (0.0, 0.0);
        for j in 0..4 {
            let c = 0.5 * (self.k_min[j] + self.k_max[j]);
            let w2 = (self.k_max[j] - self.k_min[j]).powi(2).max(1e-300);
            num += v[j] * (c - kp[j]) / w2;
            den += v[j] * v[j] / w2;
        }
        let sigma = (num / den).clamp(lo.min(hi), hi.max(lo));
        let k = DVector::from_fn(4, |j, _| {
            (kp[j] + sigma * v[j]).clamp(self.k_min[j], self.k_max[j])
        });
        k.iter().all(|x| x.is_finite()).then_some(k)
    }

    /// Eq. 31 by BVLS, then the tie-break by enumerating active sets: the reference solver,
    /// for any shape and any target (the fast path of [`Self::solve`] agrees with it).
    pub fn solve_by_active_sets(
        &self,
        target: OperationalStiffness,
    ) -> Result<Allocation, AllocationError> {
        let t = target.to_vector();
        if t.iter().any(|v| !v.is_finite()) {
            return Err(AllocationError::NonFinite("target stiffness"));
        }
        let k_star = bvls(&self.s, &t, &self.k_min, &self.k_max)?;
        let y_star = &self.s * &k_star;
        let rank = self
            .s
            .clone()
            .svd(false, false)
            .rank(1e-12 * self.s.abs().max().max(1e-300));
        let optimal_set_dim = self.s.ncols() - rank;
        let k = if optimal_set_dim > 0 {
            self.tie_break(&y_star).unwrap_or(k_star)
        } else {
            k_star
        };
        Ok(self.allocation(k, target, &t, optimal_set_dim))
    }

    /// The allocation `k` gives for `target`: what it achieves and which bounds it sits on.
    fn allocation(
        &self,
        k: DVector<f64>,
        target: OperationalStiffness,
        t: &DVector<f64>,
        optimal_set_dim: usize,
    ) -> Allocation {
        let achieved = &self.s * &k;
        let residual = (&achieved - t).norm();
        let scale = t
            .norm()
            .max(self.s.abs().max() * self.k_max.abs().max())
            .max(1e-12);
        let at_bound = (0..k.len())
            .map(|j| {
                let tol = 1e-9 * (self.k_max[j] - self.k_min[j]).max(1e-12);
                if k[j] <= self.k_min[j] + tol {
                    -1
                } else if k[j] >= self.k_max[j] - tol {
                    1
                } else {
                    0
                }
            })
            .collect();
        Allocation {
            k,
            achieved: OperationalStiffness::from_vector(&achieved),
            target,
            residual,
            feasible: residual <= 1e-9 * scale,
            at_bound,
            optimal_set_dim,
        }
    }

    /// The centre-most k in {S·k = y, bounds} by active-set enumeration.
    fn tie_break(&self, y: &DVector<f64>) -> Option<DVector<f64>> {
        let n = self.s.ncols();
        let c = (&self.k_min + &self.k_max) / 2.0;
        let w2 = (&self.k_max - &self.k_min).map(|w| (w * w).max(1e-300));
        let mut best: Option<(f64, DVector<f64>)> = None;
        for code in 0..3usize.pow(n as u32) {
            let (mut k, free) = assignment(code, n, &self.k_min, &self.k_max);
            if free.is_empty() {
                if (&self.s * &k - y).norm() <= 1e-9 * y.norm().max(1.0) {
                    consider(&mut best, &k, &c, &w2);
                }
                continue;
            }
            // Free variables: minimise Σ (z−c)²/w² s.t. S_F z = y − S_B k_B, solved as
            // z = c_F + W_F S_Fᵀ λ with (S_F W_F S_Fᵀ) λ = rhs − S_F c_F (pseudo-inverse).
            let sf = self.s.select_columns(&free);
            let wf = DMatrix::from_diagonal(&DVector::from_iterator(
                free.len(),
                free.iter().map(|&j| w2[j]),
            ));
            let mut fixed = k.clone();
            for &j in &free {
                fixed[j] = 0.0;
            }
            let rhs = y - &self.s * &fixed;
            let cf = DVector::from_iterator(free.len(), free.iter().map(|&j| c[j]));
            let m = &sf * &wf * sf.transpose();
            let Ok(lambda) = m.svd(true, true).solve(
                &(&rhs - &sf * &cf),
                1e-12 * (&sf * &wf * sf.transpose()).abs().max().max(1e-300),
            ) else {
                continue;
            };
            let z = &cf + &wf * sf.transpose() * lambda;
            if (&sf * &z - &rhs).norm() > 1e-9 * y.norm().max(1.0) {
                continue;
            }
            let inside = free.iter().enumerate().all(|(i, &j)| {
                let tol = 1e-12 * (self.k_max[j] - self.k_min[j]).max(1.0);
                z[i] >= self.k_min[j] - tol && z[i] <= self.k_max[j] + tol
            });
            if inside {
                for (i, &j) in free.iter().enumerate() {
                    k[j] = z[i].clamp(self.k_min[j], self.k_max[j]);
                }
                consider(&mut best, &k, &c, &w2);
            }
        }
        best.map(|(_, k)| k)
    }
}

fn consider(
    best: &mut Option<(f64, DVector<f64>)>,
    k: &DVector<f64>,
    c: &DVector<f64>,
    w2: &DVector<f64>,
) {
    let cost: f64 = (0..k.len()).map(|j| (k[j] - c[j]).powi(2) / w2[j]).sum();
    if best.as_ref().is_none_or(|(b, _)| cost < *b) {
        *best = Some((cost, k.clone()));
    }
}

/// Decodes an active-set assignment: digit 0 free, 1 at lower, 2 at upper bound.
fn assignment(
    mut code: usize,
    n: usize,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
) -> (DVector<f64>, Vec<usize>) {
    let mut k = DVector::zeros(n);
    let mut free = Vec::new();
    for j in 0..n {
        match code % 3 {
            0 => free.push(j),
            1 => k[j] = lo[j],
            _ => k[j] = hi[j],
        }
        code /= 3;
    }
    (k, free)
}

/// Bounded-variable least squares: min ½‖A·x − b‖² s.t. lo ≤ x ≤ hi (Stark & Parker 1995).
///
/// Active-set method: variables sit at a bound or are free; the free ones solve the
/// unconstrained sub-problem (by SVD, so rank deficiency is fine); a step that would leave
/// the box is cut at the first bound hit. It stops when the KKT conditions hold.
pub fn bvls(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
) -> Result<DVector<f64>, AllocationError> {
    let n = a.ncols();
    if a.nrows() != b.len() || lo.len() != n || hi.len() != n {
        return Err(AllocationError::Dimension {
            rows: a.nrows(),
            cols: n,
            bounds: lo.len(),
            target: b.len(),
        });
    }
    // 0 free, −1 at lower, +1 at upper. Start with everything at the lower bound.
    let mut state = vec![-1i8; n];
    let mut x = lo.clone();
    let scale = a.abs().max().max(1e-300) * (b.norm() + (a * hi).norm()).max(1e-300);
    let kkt_tol = 1e-12 * scale;
    let max_iter = 20 * n + 100;
    for _ in 0..max_iter {
        let w = a.transpose() * (b - a * &x); // −gradient
        // Most violated bound constraint.
        let mut pick: Option<(usize, f64)> = None;
        for j in 0..n {
            let v = match state[j] {
                -1 => w[j],
                1 => -w[j],
                _ => continue,
            };
            if v > kkt_tol && pick.is_none_or(|(_, best)| v > best) && lo[j] < hi[j] {
                pick = Some((j, v));
            }
        }
        let Some((t, _)) = pick else {
            return Ok(x);
        };
        state[t] = 0;
        // Inner loop: move towards the free sub-problem's solution, cutting at bounds.
        loop {
            let free: Vec<usize> = (0..n).filter(|&j| state[j] == 0).collect();
            let z = free_solution(a, b, &x, &free);
            let inside = free
                .iter()
                .enumerate()
                .all(|(i, &j)| z[i] > lo[j] && z[i] < hi[j]);
            if inside {
                for (i, &j) in free.iter().enumerate() {
                    x[j] = z[i];
                }
                break;
            }
            // Largest step α ∈ [0, 1] along z − x_F that stays in the box.
            let mut alpha: f64 = 1.0;
            for (i, &j) in free.iter().enumerate() {
                let d = z[i] - x[j];
                if z[i] <= lo[j] && d < 0.0 {
                    alpha = alpha.min((lo[j] - x[j]) / d);
                } else if z[i] >= hi[j] && d > 0.0 {
                    alpha = alpha.min((hi[j] - x[j]) / d);
                }
            }
            let alpha = alpha.clamp(0.0, 1.0);
            for (i, &j) in free.iter().enumerate() {
                x[j] += alpha * (z[i] - x[j]);
                let span = (hi[j] - lo[j]).max(1e-300);
                if x[j] <= lo[j] + 1e-14 * span {
                    x[j] = lo[j];
                    state[j] = -1;
                } else if x[j] >= hi[j] - 1e-14 * span {
                    x[j] = hi[j];
                    state[j] = 1;
                }
            }
            if free.iter().all(|&j| state[j] != 0) {
                break;
            }
        }
    }
    Err(AllocationError::NoConvergence(max_iter))
}

/// Least-squares values of the free variables with the others held (minimum norm).
fn free_solution(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    x: &DVector<f64>,
    free: &[usize],
) -> DVector<f64> {
    let af = a.select_columns(free);
    let mut fixed = x.clone();
    for &j in free {
        fixed[j] = 0.0;
    }
    let rhs = b - a * fixed;
    let eps = 1e-13 * af.abs().max().max(1e-300);
    af.svd(true, true)
        .solve(&rhs, eps)
        .unwrap_or_else(|_| DVector::from_iterator(free.len(), free.iter().map(|&j| x[j])))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planar::{Elbow, FiveBar, PlanarRobot, SerialArm, s_matrix};

    /// Independent optimum: enumerate every active set (free / lower / upper), solve the free
    /// least-squares sub-problem, keep the feasible candidate with the least objective.
    fn enumerate_optimum(
        a: &DMatrix<f64>,
        b: &DVector<f64>,
        lo: &DVector<f64>,
        hi: &DVector<f64>,
    ) -> f64 {
        let n = a.ncols();
        let mut best = f64::INFINITY;
        for code in 0..3usize.pow(n as u32) {
            let (mut x, free) = assignment(code, n, lo, hi);
            if !free.is_empty() {
                let z = free_solution(a, b, &x, &free);
                if free
                    .iter()
                    .enumerate()
                    .any(|(i, &j)| z[i] < lo[j] - 1e-12 || z[i] > hi[j] + 1e-12)
                {
                    continue;
                }
                for (i, &j) in free.iter().enumerate() {
                    x[j] = z[i];
                }
            }
            best = best.min(0.5 * (a * &x - b).norm_squared());
        }
        best
    }

    /// A small deterministic generator (xorshift) so the test needs no RNG crate.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn parallel_problem(x: f64, y: f64) -> AllocationProblem {
        let robot = PlanarRobot::FiveBar(FiveBar::example());
        let c = robot.at_position(x, y).unwrap();
        AllocationProblem::new(
            s_matrix(&c.g_u_a),
            DVector::from_vec(vec![0.258, 0.175, 0.258, 0.183]),
            DVector::from_vec(vec![50.0, 50.0, 60.0, 50.0]),
        )
        .unwrap()
    }

    #[test]
    fn bvls_matches_active_set_enumeration_on_random_problems() {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        for trial in 0..300 {
            let n = 2 + trial % 3;
            let m = 2 + (trial / 3) % 3;
            let a = DMatrix::from_fn(m, n, |_, _| rng.next() * 2.0 - 1.0);
            let b = DVector::from_fn(m, |_, _| rng.next() * 4.0 - 2.0);
            let lo = DVector::from_fn(n, |_, _| rng.next() - 0.5);
            let hi = DVector::from_fn(n, |i, _| lo[i] + 0.1 + rng.next());
            let x = bvls(&a, &b, &lo, &hi).unwrap();
            assert!((0..n).all(|j| x[j] >= lo[j] && x[j] <= hi[j]));
            let f = 0.5 * (&a * &x - &b).norm_squared();
            let f_enum = enumerate_optimum(&a, &b, &lo, &hi);
            assert!(
                (f - f_enum).abs() <= 1e-10 * (1.0 + f_enum),
                "trial {trial}: bvls {f} vs enumeration {f_enum}"
            );
        }
    }

    #[test]
    fn decoupled_targets_are_met_exactly_on_the_five_bar() {
        // Paper B: 12.5, 25, 37.5 % of the range with k_xy = 0; residual 6.2e-16 with lsqlin.
        let p = parallel_problem(0.075, 0.2);
        for percent in [12.5, 25.0, 37.5] {
            let t = p.decoupled_target(percent).unwrap();
            let a = p.solve(t).unwrap();
            assert!(a.feasible, "{percent} %: residual {}", a.residual);
            assert!(
                a.residual < 1e-9 * t.xx.abs().max(t.yy.abs()),
                "residual {}",
                a.residual
            );
            assert!(a.achieved.xy.abs() < 1e-9 * t.xx);
            assert_eq!(a.optimal_set_dim, 1);
            for j in 0..4 {
                assert!(a.k[j] >= p.k_min[j] && a.k[j] <= p.k_max[j]);
            }
        }
    }

    #[test]
    fn tie_break_matches_the_closed_form_along_the_null_space() {
        // With one null direction v of S, the optima are k* + t·v for t in an interval; the
        // centre-most one minimises Σ((k*_i + t·v_i − c_i)/w_i)² there: a clamped quadratic.
        let p = parallel_problem(0.075, 0.2);
        let t = p.decoupled_target(25.0).unwrap();
        let a = p.solve(t).unwrap();
        // The null direction: the eigenvector of SᵀS with the smallest eigenvalue.
        let eig = (p.s.transpose() * &p.s).symmetric_eigen();
        let imin = eig.eigenvalues.imin();
        let v: DVector<f64> = eig.eigenvectors.column(imin).into_owned();
        assert!((&p.s * &v).norm() < 1e-9 * p.s.norm());
        let c = (&p.k_min + &p.k_max) / 2.0;
        let w2 = (&p.k_max - &p.k_min).map(|w| w * w);
        let k0 = &a.k;
        let (mut t_lo, mut t_hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for j in 0..4 {
            if v[j].abs() > 1e-15 {
                let (ta, tb) = ((p.k_min[j] - k0[j]) / v[j], (p.k_max[j] - k0[j]) / v[j]);
                t_lo = t_lo.max(ta.min(tb));
                t_hi = t_hi.min(ta.max(tb));
            }
        }
        let num: f64 = (0..4).map(|j| v[j] * (c[j] - k0[j]) / w2[j]).sum();
        let den: f64 = (0..4).map(|j| v[j] * v[j] / w2[j]).sum();
        let t_star = (num / den).clamp(t_lo, t_hi);
        // The solver's answer is already the optimum: the best move along v is zero.
        assert!(
            t_star.abs() < 1e-9 * (t_hi - t_lo),
            "t* = {t_star} in [{t_lo}, {t_hi}]"
        );
        assert!(t_hi - t_lo > 1e-3, "the optimal set is a real segment");
    }

    #[test]
    fn closed_form_agrees_with_the_active_set_solver_on_ten_thousand_problems() {
        // Random poses of the five-bar, random bounds, and targets half of them met exactly
        // (S·k of a k in the box: the closed form) and half anywhere (mostly infeasible: the
        // fallback). Same k within 1e-9 of each joint's range, same achieved stiffness.
        let robot = PlanarRobot::FiveBar(FiveBar::example());
        let mut rng = Rng(0x2545_F491_4F6C_DD1D);
        let (mut closed, mut solved) = (0, 0);
        while solved < 10_000 {
            let (x, y) = (0.03 + 0.09 * rng.next(), 0.15 + 0.1 * rng.next());
            let Ok(c) = robot.at_position(x, y) else {
                continue;
            };
            let lo = DVector::from_fn(4, |_, _| 0.1 + rng.next());
            let hi = DVector::from_fn(4, |i, _| lo[i] + 1.0 + 80.0 * rng.next());
            let p = AllocationProblem::new(s_matrix(&c.g_u_a), lo.clone(), hi.clone()).unwrap();
            let target = if solved % 2 == 0 {
                let k = DVector::from_fn(4, |i, _| lo[i] + (hi[i] - lo[i]) * rng.next());
                OperationalStiffness::from_vector(&(&p.s * k))
            } else {
                let r = p.extent();
                OperationalStiffness {
                    xx: r.min.xx + (r.max.xx - r.min.xx) * rng.next(),
                    xy: r.min.xy + (r.max.xy - r.min.xy) * rng.next(),
                    yy: r.min.yy + (r.max.yy - r.min.yy) * rng.next(),
                }
            };
            let t = target.to_vector();
            closed += usize::from(p.solve_along_null_space(&t).is_some());
            let (fast, reference) = (
                p.solve(target).unwrap(),
                p.solve_by_active_sets(target).unwrap(),
            );
            for j in 0..4 {
                assert!(
                    (fast.k[j] - reference.k[j]).abs() <= 1e-9 * (hi[j] - lo[j]),
                    "problem {solved}, joint {j}: {} vs {}",
                    fast.k[j],
                    reference.k[j]
                );
            }
            assert_eq!(fast.feasible, reference.feasible, "problem {solved}");
            assert_eq!(fast.optimal_set_dim, reference.optimal_set_dim);
            solved += 1;
        }
        // Both paths were exercised.
        assert!(closed >= 5_000, "closed form on {closed} of 10 000");
        assert!(closed < 10_000, "the fallback never ran");
    }

    #[test]
    fn serial_robot_cannot_decouple_and_says_so() {
        // Two joints, three targets: generally no exact decoupled solution.
        let arm = PlanarRobot::Serial(SerialArm::new(0.15, 0.15, Elbow::Negative).unwrap());
        let c = arm.at_position(0.075, 0.2).unwrap();
        let p = AllocationProblem::new(
            s_matrix(&c.g_u_a),
            DVector::from_vec(vec![0.258, 0.175]),
            DVector::from_vec(vec![50.0, 50.0]),
        )
        .unwrap();
        let t = p.decoupled_target(25.0).unwrap();
        let a = p.solve(t).unwrap();
        assert!(!a.feasible);
        assert!(a.residual > 1.0);
        assert_eq!(a.optimal_set_dim, 0);
    }

    #[test]
    fn out_of_range_target_is_reported_infeasible_with_bounds_hit() {
        let p = parallel_problem(0.075, 0.2);
        let e = p.extent();
        let t = OperationalStiffness {
            xx: 2.0 * e.max.xx,
            xy: 0.0,
            yy: 2.0 * e.max.yy,
        };
        let a = p.solve(t).unwrap();
        assert!(!a.feasible);
        assert!(a.at_bound.contains(&1));
    }

    #[test]
    fn bad_problems_are_errors() {
        let s = DMatrix::from_element(3, 2, 1.0);
        assert!(
            AllocationProblem::new(
                s.clone(),
                DVector::from_vec(vec![1.0]),
                DVector::from_vec(vec![2.0, 2.0])
            )
            .is_err()
        );
        assert!(matches!(
            AllocationProblem::new(
                s.clone(),
                DVector::from_vec(vec![3.0, 0.0]),
                DVector::from_vec(vec![2.0, 2.0])
            ),
            Err(AllocationError::Bounds { joint: 0, .. })
        ));
        let p = AllocationProblem::new(
            s,
            DVector::from_vec(vec![0.0, 0.0]),
            DVector::from_vec(vec![2.0, 2.0]),
        )
        .unwrap();
        assert!(
            p.solve(OperationalStiffness {
                xx: f64::NAN,
                xy: 0.0,
                yy: 0.0
            })
            .is_err()
        );
        assert!(p.decoupled_target(120.0).is_err());
    }
}
