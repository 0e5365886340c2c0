//! Normal equations of arrowhead shape, solved by the Schur complement.
//!
//! The reprojection refinement with per-pose robot corrections has `g` global parameters (the two
//! transforms, the lens, the board's scale: at most 22) and six more per frame (that frame's
//! flange correction). Every corner touches the global parameters and its own frame's six, so
//! `JᵀJ` is an arrowhead: a dense `g × g` corner, a dense border, and 6 × 6 blocks down the rest
//! of the diagonal with zeros between them.
//!
//! ```text
//!     | A   B₁  B₂  … |        S = A − Σ Bₖ Dₖ⁻¹ Bₖᵀ        (g × g, the Schur complement)
//! H = | B₁ᵀ D₁       |        S x_g = r_g − Σ Bₖ Dₖ⁻¹ rₖ
//!     | B₂ᵀ     D₂   |        xₖ = Dₖ⁻¹ (rₖ − Bₖᵀ x_g)
//! ```
//!
//! A dense Cholesky of `H` costs `(g + 6m)³ / 3` for `m` frames: 0.6 G flops a factorisation at
//! 200 frames, and its inverse (the covariance, the noise estimate's redundancy) three times
//! that, which is where a 200-sample session spent most of its solve. The Schur complement costs
//! `m · (6³ + 2·6·g² )`: linear in the frames. Both are exact; they differ by rounding only.

use nalgebra::{Cholesky, Const, DMatrix, DVector, Dyn, OMatrix, SMatrix, SVector};

/// The size of each diagonal block (a frame's flange correction: rotation and translation).
pub(crate) const BLOCK: usize = 6;

/// How a problem's `JᵀJ` is laid out, for [`crate::lm::minimize_normal`] to solve it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Structure {
    /// No structure used: one Cholesky of the whole matrix.
    Dense,
    /// `global` leading parameters, then blocks of [`BLOCK`] that only the global ones couple.
    Arrow {
        /// The number of global parameters.
        global: usize,
    },
}

type Block = SMatrix<f64, BLOCK, BLOCK>;

/// The factorised pieces of an arrowhead matrix: each diagonal block's Cholesky, `Dₖ⁻¹ Bₖᵀ`,
/// and the Schur complement's Cholesky.
struct Factors {
    global: usize,
    blocks: Vec<Cholesky<f64, Const<BLOCK>>>,
    /// `Dₖ⁻¹ Bₖᵀ`, 6 × g each.
    block_inv_border: Vec<OMatrix<f64, Const<BLOCK>, Dyn>>,
    schur: Cholesky<f64, Dyn>,
}

/// Factorises `h` plus `damping · diag(h)` (Marquardt's scaling; each diagonal entry at least
/// 1e-12 before scaling, as the dense solver does) as an arrowhead with `global` leading
/// parameters; `None` when a block or the Schur complement is not positive definite.
fn factor(h: &DMatrix<f64>, global: usize, damping: f64) -> Option<Factors> {
    let n = h.nrows();
    debug_assert!(n >= global && (n - global).is_multiple_of(BLOCK));
    let damp = |i: usize| damping * h[(i, i)].max(1e-12);
    let mut schur = h.view((0, 0), (global, global)).clone_owned();
    for i in 0..global {
        schur[(i, i)] += damp(i);
    }
    let frames = (n - global) / BLOCK;
    let mut blocks = Vec::with_capacity(frames);
    let mut block_inv_border = Vec::with_capacity(frames);
    for k in 0..frames {
        let o = global + BLOCK * k;
        let mut d: Block = h.fixed_view::<BLOCK, BLOCK>(o, o).into();
        for i in 0..BLOCK {
            d[(i, i)] += damp(o + i);
        }
        let chol = d.cholesky()?;
        // Bₖᵀ is the block's rows of the border (6 × g).
        let border_t = h.generic_view((o, 0), (Const::<BLOCK>, Dyn(global)));
        let inv_border = chol.solve(&border_t);
        schur -= border_t.transpose() * &inv_border;
        blocks.push(chol);
        block_inv_border.push(inv_border);
    }
    Some(Factors {
        global,
        blocks,
        block_inv_border,
        schur: schur.cholesky()?,
    })
}

impl Factors {
    /// `x` with `(H + damping) x = rhs`.
    fn solve(&self, rhs: &DVector<f64>) -> DVector<f64> {
        let g = self.global;
        let block_rhs =
            |k: usize| -> SVector<f64, BLOCK> { rhs.fixed_rows::<BLOCK>(g + BLOCK * k).into() };
        let mut reduced = rhs.rows(0, g).clone_owned();
        for (k, inv_border) in self.block_inv_border.iter().enumerate() {
            // r_g − Bₖ Dₖ⁻¹ rₖ, with Bₖ Dₖ⁻¹ = (Dₖ⁻¹ Bₖᵀ)ᵀ (D symmetric).
            reduced -= inv_border.transpose() * block_rhs(k);
        }
        let x_global = self.schur.solve(&reduced);
        let mut x = DVector::zeros(rhs.len());
        x.rows_mut(0, g).copy_from(&x_global);
        for (k, chol) in self.blocks.iter().enumerate() {
            // xₖ = Dₖ⁻¹ rₖ − (Dₖ⁻¹ Bₖᵀ) x_g.
            let xk = chol.solve(&block_rhs(k)) - &self.block_inv_border[k] * &x_global;
            x.fixed_rows_mut::<BLOCK>(g + BLOCK * k).copy_from(&xk);
        }
        x
    }
}

/// `x` with `(h + damping · diag(h)) x = rhs` for a matrix of `structure`; `None` when the
/// damped matrix is not positive definite.
pub(crate) fn solve_damped(
    h: &DMatrix<f64>,
    rhs: &DVector<f64>,
    damping: f64,
    structure: Structure,
) -> Option<DVector<f64>> {
    match structure {
        Structure::Arrow { global } => Some(factor(h, global, damping)?.solve(rhs)),
        Structure::Dense => {
            let mut a = h.clone();
            for i in 0..a.nrows() {
                a[(i, i)] += damping * h[(i, i)].max(1e-12);
            }
            Some(a.cholesky()?.solve(rhs))
        }
    }
}

/// What a covariance is read for: the global parameters' block of `H⁻¹` and the diagonal of
/// the rest.
#[derive(Debug, Clone)]
pub(crate) struct InverseParts {
    /// `(H⁻¹)` over the global parameters (`g × g`; the whole inverse for a dense matrix).
    pub global: DMatrix<f64>,
    /// The diagonal of `H⁻¹` past the global parameters (empty for a dense matrix).
    pub tail_diagonal: Vec<f64>,
}

impl InverseParts {
    /// The `i`-th diagonal entry of `H⁻¹` (a parameter's variance before scaling).
    pub(crate) fn variance(&self, i: usize) -> f64 {
        let g = self.global.nrows();
        if i < g {
            self.global[(i, i)]
        } else {
            self.tail_diagonal[i - g]
        }
    }
}

/// The parts of `h⁻¹` a covariance needs, for a matrix of `structure`; `None` when `h` is not
/// positive definite. For an arrowhead: `S⁻¹` over the global parameters and, per block,
/// `diag(Dₖ⁻¹ + Dₖ⁻¹ Bₖᵀ S⁻¹ Bₖ Dₖ⁻¹)`.
pub(crate) fn inverse_parts(h: &DMatrix<f64>, structure: Structure) -> Option<InverseParts> {
    match structure {
        Structure::Dense => Some(InverseParts {
            global: h.clone().cholesky()?.inverse(),
            tail_diagonal: Vec::new(),
        }),
        Structure::Arrow { global } => {
            let factors = factor(h, global, 0.0)?;
            let schur_inverse = factors.schur.inverse();
            let mut tail_diagonal = Vec::with_capacity(factors.blocks.len() * BLOCK);
            for (chol, inv_border) in factors.blocks.iter().zip(&factors.block_inv_border) {
                let block_inverse = chol.inverse();
                let coupled = inv_border * &schur_inverse * inv_border.transpose();
                tail_diagonal.extend((0..BLOCK).map(|i| block_inverse[(i, i)] + coupled[(i, i)]));
            }
            Some(InverseParts {
                global: schur_inverse,
                tail_diagonal,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic value in (−1, 1) for each (seed, index): the tests need varied numbers,
    /// not random ones.
    fn value(seed: u64, index: usize) -> f64 {
        ((seed as f64 * 12.9898 + index as f64 * 78.233).sin() * 43_758.545).fract()
    }

    /// `JᵀJ` of a varied arrowhead Jacobian: each of `frames` groups of rows touches the `global`
    /// columns and its own six (scaled by `block_scale`), plus a prior row per block parameter
    /// (as the robot prior adds).
    fn arrow_normal_scaled(
        global: usize,
        frames: usize,
        seed: u64,
        block_scale: f64,
    ) -> DMatrix<f64> {
        let n = global + BLOCK * frames;
        let mut h = DMatrix::zeros(n, n);
        let mut index = 0;
        let mut next = || {
            index += 1;
            value(seed, index)
        };
        for k in 0..frames {
            for _ in 0..30 {
                let mut row = DVector::zeros(n);
                for c in 0..global {
                    row[c] = next();
                }
                for c in 0..BLOCK {
                    row[global + BLOCK * k + c] = next() * block_scale;
                }
                h += &row * row.transpose();
            }
            for c in 0..BLOCK {
                h[(global + BLOCK * k + c, global + BLOCK * k + c)] += block_scale * block_scale;
            }
        }
        h
    }

    fn arrow_normal(global: usize, frames: usize, seed: u64) -> DMatrix<f64> {
        arrow_normal_scaled(global, frames, seed, 1.0)
    }

    #[test]
    fn the_schur_solve_is_the_dense_solve() {
        for (global, frames, seed) in [(12, 1, 1), (21, 20, 2), (22, 60, 3)] {
            let h = arrow_normal(global, frames, seed);
            let rhs = DVector::from_fn(h.nrows(), |i, _| (i as f64 * 0.37).sin());
            for damping in [0.0, 1e-4, 10.0] {
                let dense = solve_damped(&h, &rhs, damping, Structure::Dense).unwrap();
                let arrow = solve_damped(&h, &rhs, damping, Structure::Arrow { global }).unwrap();
                let scale = dense.amax();
                assert!(
                    (&dense - &arrow).amax() <= 1e-9 * scale,
                    "g {global}, {frames} frames, damping {damping}: differ by {}",
                    (&dense - &arrow).amax()
                );
            }
        }
    }

    /// Columns of very different scales (radians beside pixels) make the Schur complement
    /// cancel; the solve still answers its system to rounding (backward stable), as the dense
    /// one does.
    #[test]
    fn the_schur_solve_answers_a_badly_scaled_system_to_rounding() {
        let global = 21;
        let h = arrow_normal_scaled(global, 40, 5, 1e3);
        let rhs = DVector::from_fn(h.nrows(), |i, _| (i as f64 * 0.37).sin());
        for damping in [0.0, 1e-4] {
            let mut damped = h.clone();
            for i in 0..h.nrows() {
                damped[(i, i)] += damping * h[(i, i)];
            }
            for structure in [Structure::Dense, Structure::Arrow { global }] {
                let x = solve_damped(&h, &rhs, damping, structure).unwrap();
                let residual = (&damped * &x - &rhs).norm() / (damped.norm() * x.norm());
                assert!(
                    residual < 1e-13,
                    "{structure:?}, damping {damping}: {residual}"
                );
            }
        }
    }

    #[test]
    fn the_schur_inverse_parts_are_the_dense_inverse() {
        let (global, frames) = (21, 30);
        let h = arrow_normal(global, frames, 7);
        let dense = h.clone().cholesky().unwrap().inverse();
        let parts = inverse_parts(&h, Structure::Arrow { global }).unwrap();
        let global_block = dense.view((0, 0), (global, global));
        assert!((global_block - &parts.global).amax() <= 1e-9 * global_block.amax());
        assert_eq!(parts.tail_diagonal.len(), BLOCK * frames);
        for i in 0..h.nrows() {
            let (got, want) = (parts.variance(i), dense[(i, i)]);
            assert!(
                (got - want).abs() <= 1e-9 * want.abs(),
                "{i}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn a_singular_block_is_refused_not_solved() {
        let (global, frames) = (12, 3);
        let mut h = arrow_normal(global, frames, 4);
        // The second frame's block carries no information at all.
        let o = global + BLOCK;
        for i in 0..h.nrows() {
            for j in o..o + BLOCK {
                h[(i, j)] = 0.0;
                h[(j, i)] = 0.0;
            }
        }
        let rhs = DVector::from_element(h.nrows(), 1.0);
        assert!(solve_damped(&h, &rhs, 0.0, Structure::Arrow { global }).is_none());
        assert!(inverse_parts(&h, Structure::Arrow { global }).is_none());
        // Damping makes it solvable, as in the dense solve (each diagonal at least 1e-12).
        assert!(solve_damped(&h, &rhs, 1.0, Structure::Arrow { global }).is_some());
    }
}
