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
//!
//! The matrix is built and kept as those parts ([`Arrowhead`]), never whole: the whole of it
//! grows with the square of the frames (1,000 frames: 289 MB, zeroed at every iteration) where
//! the parts grow with the frames (1,000 frames: about 1 MB).

use nalgebra::allocator::Allocator;
use nalgebra::{
    Cholesky, Const, DMatrix, DVector, DefaultAllocator, Dim, Dyn, OMatrix, SMatrix, SVector,
};

/// The size of each diagonal block (a frame's flange correction: rotation and translation).
pub(crate) const BLOCK: usize = 6;

type Block = SMatrix<f64, BLOCK, BLOCK>;

/// One frame's column of the border, `Bₖ` (`g × 6`).
type Border = OMatrix<f64, Dyn, Const<BLOCK>>;

/// `JᵀJ` as a problem builds it for [`crate::lm::minimize_normal`]: one dense matrix, or an
/// arrowhead kept as its parts (see the module's note on memory).
#[derive(Debug, Clone)]
pub(crate) enum NormalMatrix {
    /// No structure used: one Cholesky of the whole matrix.
    Dense(DMatrix<f64>),
    /// Global parameters, then blocks of [`BLOCK`] that only the global ones couple.
    Arrow(Arrowhead),
}

/// The non-zero parts of an arrowhead matrix (see the module's picture).
#[derive(Debug, Clone)]
pub(crate) struct Arrowhead {
    /// `A`, the global parameters' block (`g × g`).
    pub(crate) corner: DMatrix<f64>,
    /// `Bₖ`, each frame's column of the border (`g × 6`; the row of the border is its transpose).
    pub(crate) border: Vec<Border>,
    /// `Dₖ`, each frame's diagonal block.
    pub(crate) blocks: Vec<Block>,
}

impl Arrowhead {
    /// The zero matrix of `global` global parameters and `frames` blocks.
    pub(crate) fn zeros(global: usize, frames: usize) -> Arrowhead {
        Arrowhead {
            corner: DMatrix::zeros(global, global),
            border: vec![Border::zeros(global); frames],
            blocks: vec![Block::zeros(); frames],
        }
    }

    /// The number of global parameters.
    fn global(&self) -> usize {
        self.corner.nrows()
    }

    /// The whole matrix (tests compare it with a dense product).
    #[cfg(test)]
    pub(crate) fn to_dense(&self) -> DMatrix<f64> {
        let g = self.global();
        let n = g + BLOCK * self.blocks.len();
        let mut h = DMatrix::zeros(n, n);
        h.view_mut((0, 0), (g, g)).copy_from(&self.corner);
        for (k, (b, d)) in self.border.iter().zip(&self.blocks).enumerate() {
            let o = g + BLOCK * k;
            h.view_mut((0, o), (g, BLOCK)).copy_from(b);
            h.view_mut((o, 0), (BLOCK, g)).copy_from(&b.transpose());
            h.fixed_view_mut::<BLOCK, BLOCK>(o, o).copy_from(d);
        }
        h
    }

    /// The parts of a whole arrowhead matrix `h` with `global` global parameters (what lies
    /// outside them is dropped).
    #[cfg(test)]
    pub(crate) fn from_dense(h: &DMatrix<f64>, global: usize) -> Arrowhead {
        let frames = (h.nrows() - global) / BLOCK;
        let o = |k: usize| global + BLOCK * k;
        Arrowhead {
            corner: h.view((0, 0), (global, global)).clone_owned(),
            border: (0..frames)
                .map(|k| {
                    h.generic_view((0, o(k)), (Dyn(global), Const::<BLOCK>))
                        .clone_owned()
                })
                .collect(),
            blocks: (0..frames)
                .map(|k| h.fixed_view::<BLOCK, BLOCK>(o(k), o(k)).into())
                .collect(),
        }
    }
}

impl NormalMatrix {
    /// The whole matrix (tests compare it with a dense product).
    #[cfg(test)]
    pub(crate) fn to_dense(&self) -> DMatrix<f64> {
        match self {
            NormalMatrix::Dense(h) => h.clone(),
            NormalMatrix::Arrow(arrow) => arrow.to_dense(),
        }
    }
}

/// `d` plus `damping · diag(d)` (Marquardt's scaling; each diagonal entry at least 1e-12 before
/// scaling).
fn damped<D: Dim>(mut d: OMatrix<f64, D, D>, damping: f64) -> OMatrix<f64, D, D>
where
    DefaultAllocator: Allocator<D, D>,
{
    for i in 0..d.nrows() {
        d[(i, i)] += damping * d[(i, i)].max(1e-12);
    }
    d
}

/// The factorised pieces of an arrowhead matrix: each diagonal block's Cholesky, `Dₖ⁻¹ Bₖᵀ`,
/// and the Schur complement's Cholesky.
struct Factors {
    global: usize,
    blocks: Vec<Cholesky<f64, Const<BLOCK>>>,
    /// `Dₖ⁻¹ Bₖᵀ`, 6 × g each.
    block_inv_border: Vec<OMatrix<f64, Const<BLOCK>, Dyn>>,
    schur: Cholesky<f64, Dyn>,
}

/// Factorises `h` plus `damping · diag(h)` ([`damped`]); `None` when a block or the Schur
/// complement is not positive definite.
fn factor(h: &Arrowhead, damping: f64) -> Option<Factors> {
    let global = h.global();
    let mut schur = damped(h.corner.clone(), damping);
    let mut blocks = Vec::with_capacity(h.blocks.len());
    let mut block_inv_border = Vec::with_capacity(h.blocks.len());
    for (border, block) in h.border.iter().zip(&h.blocks) {
        let chol = damped(*block, damping).cholesky()?;
        let inv_border = chol.solve(&border.transpose());
        schur -= border * &inv_border;
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

/// `x` with `(h + damping · diag(h)) x = rhs`; `None` when the damped matrix is not positive
/// definite.
pub(crate) fn solve_damped(
    h: &NormalMatrix,
    rhs: &DVector<f64>,
    damping: f64,
) -> Option<DVector<f64>> {
    match h {
        NormalMatrix::Arrow(arrow) => Some(factor(arrow, damping)?.solve(rhs)),
        NormalMatrix::Dense(h) => Some(damped(h.clone(), damping).cholesky()?.solve(rhs)),
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

/// The parts of `h⁻¹` a covariance needs; `None` when `h` is not positive definite. For an
/// arrowhead: `S⁻¹` over the global parameters and, per block,
/// `diag(Dₖ⁻¹ + Dₖ⁻¹ Bₖᵀ S⁻¹ Bₖ Dₖ⁻¹)`.
pub(crate) fn inverse_parts(h: &NormalMatrix) -> Option<InverseParts> {
    match h {
        NormalMatrix::Dense(h) => Some(InverseParts {
            global: h.clone().cholesky()?.inverse(),
            tail_diagonal: Vec::new(),
        }),
        NormalMatrix::Arrow(arrow) => {
            let factors = factor(arrow, 0.0)?;
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

    /// The whole matrix `h` kept as an arrowhead's parts.
    fn arrow_of(h: &DMatrix<f64>, global: usize) -> NormalMatrix {
        NormalMatrix::Arrow(Arrowhead::from_dense(h, global))
    }

    /// The parts give back the whole matrix they were taken from (the other tests build their
    /// arrowheads with `from_dense` and compare them with the whole matrix).
    #[test]
    fn an_arrowhead_is_its_whole_matrix() {
        let h = arrow_normal(13, 4, 9);
        assert_eq!(arrow_of(&h, 13).to_dense(), h);
    }

    #[test]
    fn the_schur_solve_is_the_dense_solve() {
        for (global, frames, seed) in [(12, 1, 1), (21, 20, 2), (22, 60, 3)] {
            let h = arrow_normal(global, frames, seed);
            let rhs = DVector::from_fn(h.nrows(), |i, _| (i as f64 * 0.37).sin());
            for damping in [0.0, 1e-4, 10.0] {
                let dense = solve_damped(&NormalMatrix::Dense(h.clone()), &rhs, damping).unwrap();
                let arrow = solve_damped(&arrow_of(&h, global), &rhs, damping).unwrap();
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
            for structure in [NormalMatrix::Dense(h.clone()), arrow_of(&h, global)] {
                let x = solve_damped(&structure, &rhs, damping).unwrap();
                let residual = (&damped * &x - &rhs).norm() / (damped.norm() * x.norm());
                assert!(
                    residual < 1e-13,
                    "{}, damping {damping}: {residual}",
                    match structure {
                        NormalMatrix::Dense(_) => "dense",
                        NormalMatrix::Arrow(_) => "arrowhead",
                    }
                );
            }
        }
    }

    #[test]
    fn the_schur_inverse_parts_are_the_dense_inverse() {
        let (global, frames) = (21, 30);
        let h = arrow_normal(global, frames, 7);
        let dense = h.clone().cholesky().unwrap().inverse();
        let parts = inverse_parts(&arrow_of(&h, global)).unwrap();
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
        let h = arrow_of(&h, global);
        assert!(solve_damped(&h, &rhs, 0.0).is_none());
        assert!(inverse_parts(&h).is_none());
        // Damping makes it solvable, as in the dense solve (each diagonal at least 1e-12).
        assert!(solve_damped(&h, &rhs, 1.0).is_some());
    }
}
