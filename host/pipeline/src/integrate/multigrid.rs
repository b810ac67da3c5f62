//! Aggregation multigrid for the masked Laplacian, used as the preconditioner of conjugate
//! gradients (Notay 2010, "An aggregation-based algebraic multigrid method"; Braess 1995).
//!
//! Level 0 is the mask's graph Laplacian on the pixel grid. Each coarser level merges 2×2 cells:
//! a coarse cell exists where any of its four children does, prolongation copies a coarse value
//! to its children and restriction sums them (P and Pᵀ), and the Galerkin operator PᵀAP is again a
//! weighted graph Laplacian on a grid whose edge weights count the fine edges joining two cells,
//! so every level keeps the same compact 4-neighbour storage and any mask shape (holes, several
//! components) is handled. Piecewise-constant aggregation under-corrects smooth errors, so the
//! coarse correction is scaled by [`OVER_CORRECTION`]. The symmetric V-cycle (a red–black
//! Gauss–Seidel sweep before the coarse correction and the same sweep in reverse colour order
//! after it; a shifted band Cholesky solve on the coarsest level) is a symmetric
//! positive-definite preconditioner, so CG converges in a number of iterations nearly
//! independent of the mask's size. The grid is a checkerboard whose two colours never neighbour
//! each other, so each half-sweep updates its nodes independently, in parallel bands on large
//! levels. (Lexicographic Gauss–Seidel chains every node to the one just updated and needs more
//! iterations: 17 instead of 15 on the warm video window of `benches/integrate.rs`, 36 instead
//! of 31 on its cold one.)
//!
//! The aggregation (coarse grids, node maps, components) depends on the mask's graph only, so
//! solves on the same mask with new edge weights (the coverage passes of one integration, the
//! passes of one reconstruction) keep it and recompute only the Galerkin operators' weights, in
//! place, and the coarsest factor ([`Multigrid::reweight`], identical to a fresh hierarchy);
//! the fine operator itself takes new weights in place too ([`GridLaplacian::update`]).
//!
//! Each V-cycle starts from zero on every level, so its first half-sweep (the even nodes, whose
//! neighbours are all still zero) is just b_k / a_kk, with no clearing of the solution first,
//! and the finest level works in the caller's r and z without copying them. The residual is
//! restricted from the even nodes alone: the forward sweep relaxes the odd ones last, so theirs
//! is zero but for rounding; and the coarse correction is prolongated to the even nodes alone:
//! the backward sweep relaxes the odd ones first, from their even neighbours, and overwrites
//! them. (The same preconditioner in exact arithmetic, for half the cost of residual and
//! prolongation.)

use super::band_cholesky::BandCholesky;
use rayon::prelude::*;

/// Marks "no neighbour".
pub(crate) const NONE: u32 = u32::MAX;
/// Scale of the coarse-grid correction (piecewise-constant aggregation under-corrects by ~2 in 2-D).
const OVER_CORRECTION: f64 = 1.8;
/// Levels are added until the coarsest has at most this many unknowns.
const COARSEST_SIZE: usize = 256;
/// Relative diagonal shift that makes the coarsest-level Cholesky factorisation possible; the
/// constant per component it would set is projected out.
const COARSE_SHIFT: f64 = 1e-8;
/// Gauss–Seidel sweeps before and after each coarse-grid correction.
const SMOOTHING_SWEEPS: usize = 1;
// The V-cycle's first pre-smoothing sweep is the one from zero.
const _: () = assert!(SMOOTHING_SWEEPS >= 1);
/// Operators (or colours) with fewer nodes run on the calling thread: handing a smaller one to
/// the thread pool costs more than it saves.
const PARALLEL_NODES: usize = 16_384;
/// Nodes per parallel task, here and in the per-node loops of every integration pass.
pub(crate) const PARALLEL_BAND: usize = 4_096;

/// A weighted graph Laplacian on a grid: node k sits at `cells[k]`; neighbours right, down, left,
/// up with their edge weights; `diag` = Σ weights + the regularising shift.
#[derive(Debug, Clone)]
pub(crate) struct GridLaplacian {
    /// Grid size (rows, columns).
    pub shape: (usize, usize),
    /// Grid position of each node, in raster order.
    pub cells: Vec<(usize, usize)>,
    /// Neighbour node (or [`NONE`]) right, down, left, up.
    pub neighbours: Vec<[u32; 4]>,
    /// Edge weight to each neighbour (0 where none).
    pub weights: Vec<[f64; 4]>,
    /// Diagonal entry.
    pub diag: Vec<f64>,
    /// Branch-free stencil: a missing neighbour points at the node itself with weight 0.
    stencil: Vec<Stencil>,
    /// The nodes of each colour of the grid's checkerboard ((row + column) even, odd): a node's
    /// neighbours all have the other colour.
    colours: [Vec<u32>; 2],
}

/// One node's row of the operator as the kernels read it: neighbour indices and weights with
/// no "missing" marker, the diagonal and its inverse, in one 64-byte cache line.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
struct Stencil {
    /// Edge weight to each neighbour (0 where none).
    weights: [f64; 4],
    /// Diagonal entry.
    diag: f64,
    /// 1 / diagonal entry.
    inverse_diag: f64,
    /// Neighbour node right, down, left, up (the node itself where none); every one is below
    /// the operator's node count ([`GridLaplacian::new`] checks it).
    neighbours: [u32; 4],
}

impl GridLaplacian {
    /// Assembles a Laplacian from its parts (see the field docs).
    pub fn new(
        shape: (usize, usize),
        cells: Vec<(usize, usize)>,
        neighbours: Vec<[u32; 4]>,
        weights: Vec<[f64; 4]>,
        diag: Vec<f64>,
    ) -> Self {
        let n = cells.len();
        assert!(
            neighbours.len() == n && weights.len() == n && diag.len() == n,
            "a Laplacian's parts must all have one entry per node"
        );
        let mut stencil: Vec<Stencil> = neighbours
            .par_iter()
            .with_min_len(PARALLEL_BAND)
            .enumerate()
            .map(|(k, nb)| {
                assert!(
                    nb.iter().all(|&j| j == NONE || (j as usize) < n),
                    "node {k} has a neighbour outside the {n} nodes"
                );
                Stencil {
                    weights: [0.0; 4],
                    diag: 0.0,
                    inverse_diag: 0.0,
                    neighbours: nb.map(|j| if j == NONE { k as u32 } else { j }),
                }
            })
            .collect();
        fill_stencil_weights(&mut stencil, &neighbours, &weights, &diag);
        let colour = |k: usize| (cells[k].0 + cells[k].1) % 2;
        let mut colours = [Vec::new(), Vec::new()];
        for (k, nb) in neighbours.iter().enumerate() {
            // Grid neighbours differ by one row or one column (the Galerkin operators' too).
            debug_assert!(
                nb.iter()
                    .all(|&j| j == NONE || colour(j as usize) != colour(k)),
                "node {k} has a neighbour that is not beside it on the grid"
            );
            colours[colour(k)].push(k as u32);
        }
        Self {
            shape,
            cells,
            neighbours,
            weights,
            diag,
            stencil,
            colours,
        }
    }

    /// Number of unknowns.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Sets new edge weights and diagonal on the same graph: `set` receives the weights and the
    /// diagonal to overwrite (one entry per node, as [`Self::new`] takes them), then the
    /// kernels' stencils follow them. The cells, neighbours and colour lists are kept, so the
    /// result equals [`Self::new`] with the new weights bit for bit without rebuilding them.
    pub fn update(&mut self, set: impl FnOnce(&mut [[f64; 4]], &mut [f64])) {
        set(&mut self.weights, &mut self.diag);
        fill_stencil_weights(
            &mut self.stencil,
            &self.neighbours,
            &self.weights,
            &self.diag,
        );
    }

    /// y = A x (in parallel bands on a large operator; every entry is one node's own sum, so
    /// the result does not depend on the bands).
    pub fn apply(&self, x: &[f64], y: &mut [f64]) {
        assert!(x.len() == self.stencil.len() && y.len() == self.stencil.len());
        let band = |(y, (stencil, xs)): (&mut [f64], (&[Stencil], &[f64]))| {
            for ((yk, st), &xk) in y.iter_mut().zip(stencil).zip(xs) {
                *yk = st.diag * xk - off_diagonal_sum(st, x);
            }
        };
        if y.len() < PARALLEL_NODES {
            band((y, (&self.stencil, x)));
        } else {
            y.par_chunks_mut(PARALLEL_BAND)
                .zip(self.stencil.par_chunks(PARALLEL_BAND))
                .zip(x.par_chunks(PARALLEL_BAND))
                .map(|((y, st), xs)| (y, (st, xs)))
                .for_each(band);
        }
    }

    /// One red–black Gauss–Seidel sweep on A x = b: the even nodes of the checkerboard, then
    /// the odd ones (`forward`), or the reverse, so that a forward sweep before and a backward
    /// one after a coarse correction keep the V-cycle symmetric. The nodes of one colour depend
    /// only on the other colour's (grid neighbours differ by one row or column; [`Self::new`]
    /// checks it in debug builds), so their updates are independent:
    /// they are computed in parallel bands into `scratch` (at least half the node count long)
    /// and then stored (Trottenberg, Oosterlee & Schüller, "Multigrid", 2001, §2.1: the
    /// red–black smoothing factor of the 5-point Laplacian is 1/4, lexicographic order's 1/2).
    fn gauss_seidel(&self, b: &[f64], x: &mut [f64], forward: bool, scratch: &mut [f64]) {
        assert!(b.len() == self.stencil.len() && x.len() == self.stencil.len());
        let order = if forward { [0, 1] } else { [1, 0] };
        for colour in order {
            self.relax_colour(colour, b, x, scratch);
        }
    }

    /// The forward sweep of [`Self::gauss_seidel`] from x = 0, without reading `x`: the even
    /// nodes' neighbours are all zero, so their update is b_k / a_kk (computed as
    /// (b_k + 0)·(1/a_kk), which is what the sweep from zero computes bit for bit when the
    /// weights are finite and non-negative); the odd nodes are set to 0 in the same pass (a
    /// missing neighbour is a zero-weight reference to the node itself) and then relaxed as
    /// usual. Equals `x.fill(0.0)` followed by a forward sweep, and saves its first half-sweep.
    fn gauss_seidel_from_zero(&self, b: &[f64], x: &mut [f64], scratch: &mut [f64]) {
        assert!(b.len() == self.stencil.len() && x.len() == self.stencil.len());
        let band = |x: &mut [f64], stencil: &[Stencil], b: &[f64], cells: &[(usize, usize)]| {
            for (((xk, st), &bk), &(r, c)) in x.iter_mut().zip(stencil).zip(b).zip(cells) {
                *xk = if (r + c) % 2 == 0 {
                    (bk + 0.0) * st.inverse_diag
                } else {
                    0.0
                };
            }
        };
        if x.len() < PARALLEL_NODES {
            band(x, &self.stencil, b, &self.cells);
        } else {
            x.par_chunks_mut(PARALLEL_BAND)
                .zip(self.stencil.par_chunks(PARALLEL_BAND))
                .zip(b.par_chunks(PARALLEL_BAND))
                .zip(self.cells.par_chunks(PARALLEL_BAND))
                .for_each(|(((x, st), b), cells)| band(x, st, b, cells));
        }
        self.relax_colour(1, b, x, scratch);
    }

    /// Relaxes the nodes of one colour of the checkerboard (their updates are independent; see
    /// [`Self::gauss_seidel`]).
    fn relax_colour(&self, colour: usize, b: &[f64], x: &mut [f64], scratch: &mut [f64]) {
        let nodes = &self.colours[colour];
        if nodes.len() < PARALLEL_NODES {
            // On the calling thread the updates go straight into `x`: a node reads only the
            // other colour's entries.
            for &k in nodes {
                let st = &self.stencil[k as usize];
                x[k as usize] = (b[k as usize] + off_diagonal_sum(st, x)) * st.inverse_diag;
            }
            return;
        }
        let relaxed = &mut scratch[..nodes.len()];
        let x_now: &[f64] = x;
        let band = |(out, ks): (&mut [f64], &[u32])| {
            for (o, &k) in out.iter_mut().zip(ks) {
                let st = &self.stencil[k as usize];
                *o = (b[k as usize] + off_diagonal_sum(st, x_now)) * st.inverse_diag;
            }
        };
        relaxed
            .par_chunks_mut(PARALLEL_BAND)
            .zip(nodes.par_chunks(PARALLEL_BAND))
            .for_each(band);
        for (&k, &v) in nodes.iter().zip(relaxed.iter()) {
            x[k as usize] = v;
        }
    }

    /// The Galerkin coarsening by 2×2 aggregation: the coarse operator and how this level's
    /// nodes map to it.
    fn coarsen(&self, regularisation: f64) -> CoarseLevel {
        let (rows, cols) = (self.shape.0.div_ceil(2), self.shape.1.div_ceil(2));
        let mut index = vec![NONE; rows * cols];
        for &(r, c) in &self.cells {
            index[(r / 2) * cols + c / 2] = 0;
        }
        let mut cells = Vec::new();
        for (i, slot) in index.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = cells.len() as u32;
                cells.push((i / cols, i % cols));
            }
        }
        let parent: Vec<u32> = self
            .cells
            .iter()
            .map(|&(r, c)| index[(r / 2) * cols + c / 2])
            .collect();
        // The coarse graph: two aggregates are neighbours where a fine edge joins them.
        let n = cells.len();
        let mut neighbours = vec![[NONE; 4]; n];
        let mut children = vec![0u32; n];
        let mut even_children = vec![[NONE; 2]; n];
        for (k, nb) in self.neighbours.iter().enumerate() {
            let pk = parent[k] as usize;
            children[pk] += 1;
            let (r, c) = self.cells[k];
            if (r + c) % 2 == 0 {
                // A 2×2 block holds two even cells, its top-left and bottom-right ones.
                let slot = usize::from(even_children[pk][0] != NONE);
                even_children[pk][slot] = k as u32;
            }
            // Right (0) and down (1) edges cover every fine edge once.
            for d in 0..2 {
                if nb[d] == NONE {
                    continue;
                }
                let pj = parent[nb[d] as usize] as usize;
                if pj != pk {
                    neighbours[pk][d] = pj as u32;
                    neighbours[pj][d + 2] = pk as u32;
                }
            }
        }
        let mut coarse = GridLaplacian::new(
            (rows, cols),
            cells,
            neighbours,
            vec![[0.0; 4]; n],
            vec![0.0; n],
        );
        self.galerkin(&mut coarse, &parent, &children, regularisation);
        CoarseLevel {
            a: coarse,
            parent,
            children,
            even_children,
        }
    }

    /// The restriction Pᵀ(b − A x) after a forward sweep, from the even nodes alone: the odd
    /// nodes were relaxed last, from the even values that are still in `x`, so their residual
    /// is zero but for rounding. `even_children[p]` holds the even nodes of aggregate p (its
    /// top-left and bottom-right cells, [`NONE`] where absent) and `coarse_b[p]` gets the sum of
    /// their residuals; each aggregate's sum is its own, so a large level is restricted in
    /// parallel bands, with no clearing of `coarse_b` and without storing the residual.
    fn restrict_even_residual(
        &self,
        b: &[f64],
        x: &[f64],
        even_children: &[[u32; 2]],
        coarse_b: &mut [f64],
    ) {
        assert!(b.len() == self.stencil.len() && x.len() == self.stencil.len());
        assert!(even_children.len() == coarse_b.len());
        let residual = |k: u32| {
            let k = k as usize;
            let st = &self.stencil[k];
            b[k] - (st.diag * x[k] - off_diagonal_sum(st, x))
        };
        let band = |(out, blocks): (&mut [f64], &[[u32; 2]])| {
            for (o, &[first, second]) in out.iter_mut().zip(blocks) {
                let mut sum = 0.0;
                if first != NONE {
                    sum += residual(first);
                }
                if second != NONE {
                    sum += residual(second);
                }
                *o = sum;
            }
        };
        if self.len() < PARALLEL_NODES {
            band((coarse_b, even_children));
        } else {
            // About PARALLEL_BAND fine nodes per task.
            coarse_b
                .par_chunks_mut(PARALLEL_BAND / 4)
                .zip(even_children.par_chunks(PARALLEL_BAND / 4))
                .for_each(band);
        }
    }

    /// Sets the weights of the Galerkin operator PᵀAP, `coarse`, on the aggregates that
    /// `parent` maps this operator's nodes to (`children` fine nodes each; the graph as
    /// [`Self::coarsen`] built it): the coarse edge weights sum the fine edges joining two
    /// aggregates, and each fine node brings its `regularisation` to its aggregate's diagonal.
    fn galerkin(
        &self,
        coarse: &mut GridLaplacian,
        parent: &[u32],
        children: &[u32],
        regularisation: f64,
    ) {
        assert!(parent.len() == self.len() && children.len() == coarse.len());
        coarse.update(|weights, diag| {
            weights.fill([0.0; 4]);
            for (k, nb) in self.neighbours.iter().enumerate() {
                let pk = parent[k] as usize;
                for d in 0..2 {
                    if nb[d] == NONE {
                        continue;
                    }
                    let pj = parent[nb[d] as usize] as usize;
                    if pj == pk {
                        continue;
                    }
                    let w = self.weights[k][d];
                    weights[pk][d] += w;
                    weights[pj][d + 2] += w;
                }
            }
            for ((dk, w), &m) in diag.iter_mut().zip(weights.iter()).zip(children) {
                *dk = w.iter().sum::<f64>() + regularisation * m as f64;
            }
        });
    }
}

/// Every node's stencil weights (0 towards a missing neighbour), diagonal and inverse diagonal
/// from the operator's parts; the stencil's neighbour indices, checked once by
/// [`GridLaplacian::new`], are left as they are.
fn fill_stencil_weights(
    stencil: &mut [Stencil],
    neighbours: &[[u32; 4]],
    weights: &[[f64; 4]],
    diag: &[f64],
) {
    assert!(
        neighbours.len() == stencil.len()
            && weights.len() == stencil.len()
            && diag.len() == stencil.len(),
        "a Laplacian's parts must all have one entry per node"
    );
    stencil
        .par_iter_mut()
        .with_min_len(PARALLEL_BAND)
        .zip(neighbours)
        .zip(weights)
        .zip(diag)
        .for_each(|(((st, nb), w), &d)| {
            st.weights = [0, 1, 2, 3].map(|i| if nb[i] == NONE { 0.0 } else { w[i] });
            st.diag = d;
            st.inverse_diag = 1.0 / d;
        });
}

/// Σ_j w_kj x_j over the neighbours of one node's stencil, where `x` has one entry per node of
/// the operator the stencil belongs to (its callers assert that).
#[inline(always)]
fn off_diagonal_sum(st: &Stencil, x: &[f64]) -> f64 {
    let [w0, w1, w2, w3] = st.weights;
    let [j0, j1, j2, j3] = st.neighbours.map(|j| j as usize);
    debug_assert!(j0.max(j1).max(j2).max(j3) < x.len());
    // SAFETY: `GridLaplacian::new` checked every neighbour index against the node count, and
    // every caller asserts that `x` has one entry per node; the four gathers are the hottest
    // loads of the solver and their bounds checks a fifth of its instructions.
    let at = |j: usize| unsafe { *x.get_unchecked(j) };
    (w0 * at(j0) + w1 * at(j1)) + (w2 * at(j2) + w3 * at(j3))
}

/// One level below the finest: its operator, the map from the next finer level's nodes, the
/// number of them in each of its nodes and which of them are even on the finer checkerboard.
struct CoarseLevel {
    a: GridLaplacian,
    parent: Vec<u32>,
    children: Vec<u32>,
    even_children: Vec<[u32; 2]>,
}

/// The multigrid V-cycle preconditioner of a [`GridLaplacian`].
pub(crate) struct Multigrid {
    levels: Vec<CoarseLevel>,
    /// Cholesky factor of the coarsest operator (shifted), if the hierarchy has coarse levels.
    coarsest: Option<BandCholesky>,
    /// Connected component of each coarsest-level node and the component sizes.
    component: Vec<usize>,
    component_size: Vec<f64>,
    /// Per level (finest first): right-hand side and solution (empty on the finest level, whose
    /// are the caller's r and z), and residual scratch.
    rhs: Vec<Vec<f64>>,
    solution: Vec<Vec<f64>>,
    residual: Vec<Vec<f64>>,
}

impl Multigrid {
    /// Builds the hierarchy below `fine` (whose diagonal carries `regularisation` per node).
    pub fn new(fine: &GridLaplacian, regularisation: f64) -> Self {
        let mut levels: Vec<CoarseLevel> = Vec::new();
        loop {
            let finer = levels.last().map_or(fine, |l| &l.a);
            if finer.len() <= COARSEST_SIZE {
                break;
            }
            let level = finer.coarsen(regularisation);
            if level.a.len() * 10 > finer.len() * 9 {
                break; // Coarsening stalled (e.g. a one-pixel-wide mask).
            }
            levels.push(level);
        }
        let coarsest = levels.last().and_then(|l| coarsest_factor(&l.a));
        let (component, component_size) = components(levels.last().map_or(fine, |l| &l.a));
        let sizes: Vec<usize> = std::iter::once(fine.len())
            .chain(levels.iter().map(|l| l.a.len()))
            .collect();
        let coarse_zeros = || {
            std::iter::once(Vec::new())
                .chain(sizes[1..].iter().map(|&n| vec![0.0; n]))
                .collect::<Vec<_>>()
        };
        Self {
            levels,
            coarsest,
            component,
            component_size,
            rhs: coarse_zeros(),
            solution: coarse_zeros(),
            residual: sizes.iter().map(|&n| vec![0.0; n]).collect(),
        }
    }

    /// Recomputes the coarse operators for new edge weights of `fine`, which must have the
    /// graph of the operator the hierarchy was built for (the same mask): the aggregates, the
    /// node maps, the components, the coarse graphs and the scratch are kept and the coarse
    /// weights overwritten in place, so the result equals [`Self::new`]`(fine, regularisation)`
    /// bit for bit at a fraction of its cost.
    pub fn reweight(&mut self, fine: &GridLaplacian, regularisation: f64) {
        for l in 0..self.levels.len() {
            let (finer_levels, rest) = self.levels.split_at_mut(l);
            let finer = finer_levels.last().map_or(fine, |f| &f.a);
            let level = &mut rest[0];
            finer.galerkin(&mut level.a, &level.parent, &level.children, regularisation);
        }
        self.coarsest = self.levels.last().and_then(|l| coarsest_factor(&l.a));
    }

    /// z = B⁻¹ r: one symmetric V-cycle from z = 0 on the finest operator `fine` (every entry
    /// of `z` is overwritten; the finest level works in `r` and `z` directly).
    pub fn precondition(&mut self, fine: &GridLaplacian, r: &[f64], z: &mut [f64]) {
        assert!(r.len() == fine.len() && z.len() == fine.len());
        let depth = self.levels.len();
        // Down: pre-smooth from zero, restrict the residual.
        for l in 0..depth {
            let (finer_rhs, coarser_rhs) = self.rhs.split_at_mut(l + 1);
            let (a, b, x): (&GridLaplacian, &[f64], &mut [f64]) = if l == 0 {
                (fine, r, &mut *z)
            } else {
                (&self.levels[l - 1].a, &finer_rhs[l], &mut self.solution[l])
            };
            let res = &mut self.residual[l];
            a.gauss_seidel_from_zero(b, x, res);
            for _ in (0..SMOOTHING_SWEEPS).skip(1) {
                a.gauss_seidel(b, x, true, res);
            }
            a.restrict_even_residual(b, x, &self.levels[l].even_children, &mut coarser_rhs[0]);
        }
        // Coarsest solve.
        let (b, x): (&[f64], &mut [f64]) = if depth == 0 {
            (r, &mut *z)
        } else {
            (&self.rhs[depth], &mut self.solution[depth])
        };
        match (&self.coarsest, depth) {
            (Some(chol), d) if d > 0 => {
                // Pseudo-inverse: no constant per component in or out (the Neumann null space).
                x.copy_from_slice(b);
                remove_component_means(x, &self.component, &self.component_size);
                chol.solve_in_place(x);
                remove_component_means(x, &self.component, &self.component_size);
            }
            _ => {
                let a = if depth == 0 {
                    fine
                } else {
                    &self.levels[depth - 1].a
                };
                let sweeps = if depth == 0 { 1 } else { 50 };
                let scratch = &mut self.residual[depth];
                x.fill(0.0);
                for _ in 0..sweeps {
                    a.gauss_seidel(b, x, true, scratch);
                    a.gauss_seidel(b, x, false, scratch);
                }
            }
        }
        // Up: prolongate the correction, post-smooth.
        for l in (0..depth).rev() {
            let (fine_part, coarse_part) = self.solution.split_at_mut(l + 1);
            let xc = &coarse_part[0];
            let (a, b, x): (&GridLaplacian, &[f64], &mut [f64]) = if l == 0 {
                (fine, r, &mut *z)
            } else {
                (&self.levels[l - 1].a, &self.rhs[l], &mut fine_part[l])
            };
            // The backward sweep relaxes the odd nodes first, from their even neighbours (their
            // own value is read only with weight 0), so the correction goes to the even ones.
            for (children, &c) in self.levels[l].even_children.iter().zip(xc) {
                for &k in children {
                    if k != NONE {
                        x[k as usize] += OVER_CORRECTION * c;
                    }
                }
            }
            for _ in 0..SMOOTHING_SWEEPS {
                a.gauss_seidel(b, x, false, &mut self.residual[l]);
            }
        }
    }
}

/// The Cholesky factor of the coarsest operator `a` with its diagonal shifted by
/// [`COARSE_SHIFT`] times its mean (`None` if it does not factor): a band factor, since a grid
/// operator in raster order couples nodes at most a row apart ([`BandCholesky`]).
fn coarsest_factor(a: &GridLaplacian) -> Option<BandCholesky> {
    let n = a.len();
    let mean_diag = a.diag.iter().sum::<f64>() / n as f64;
    let below = |k: usize| {
        a.neighbours[k]
            .iter()
            .zip(&a.weights[k])
            .filter(move |&(&j, _)| j != NONE && (j as usize) < k)
            .map(move |(&j, &w)| (k, j as usize, -w))
    };
    let bandwidth = (0..n)
        .flat_map(below)
        .map(|(k, j, _)| k - j)
        .max()
        .unwrap_or(0);
    BandCholesky::new(
        n,
        bandwidth,
        (0..n).flat_map(|k| {
            std::iter::once((k, k, a.diag[k] + COARSE_SHIFT * mean_diag)).chain(below(k))
        }),
    )
}

/// Connected component of every node of `a` and the node count of each component.
fn components(a: &GridLaplacian) -> (Vec<usize>, Vec<f64>) {
    let mut label = vec![usize::MAX; a.len()];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..a.len() {
        if label[start] != usize::MAX {
            continue;
        }
        let id = sizes.len();
        let mut size = 0usize;
        label[start] = id;
        stack.push(start);
        while let Some(k) = stack.pop() {
            size += 1;
            for &j in &a.neighbours[k] {
                if j != NONE && label[j as usize] == usize::MAX {
                    label[j as usize] = id;
                    stack.push(j as usize);
                }
            }
        }
        sizes.push(size as f64);
    }
    (label, sizes)
}

/// Subtracts from every node the mean of `v` over its component.
fn remove_component_means(v: &mut [f64], component: &[usize], size: &[f64]) {
    let mut sum = vec![0.0; size.len()];
    for (x, &c) in v.iter().zip(component) {
        sum[c] += x;
    }
    for (x, &c) in v.iter_mut().zip(component) {
        *x -= sum[c] / size[c];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit-weight Laplacian of a `rows`×`cols` mask given by `inside`.
    fn laplacian(rows: usize, cols: usize, inside: impl Fn(usize, usize) -> bool) -> GridLaplacian {
        let mask = ndarray::Array2::from_shape_fn((rows, cols), |(r, c)| inside(r, c));
        let topology = super::super::least_squares::Topology::new(&mask);
        topology.laplacian(&vec![[1.0; 2]; topology.len()])
    }

    /// A Laplacian and a hierarchy reweighted in place for new edge weights precondition
    /// exactly as ones built afresh for them, and differently from the ones they were built for
    /// (the weights reached them); what `z` held before does not matter.
    #[test]
    fn a_reweighted_hierarchy_equals_a_fresh_one() {
        let mask = ndarray::Array2::from_shape_fn((60, 75), |(r, c)| {
            let (y, x) = (r as f64 - 30.0, c as f64 - 35.0);
            x * x + y * y < 28.0 * 28.0 && !(20..26).contains(&c)
        });
        let topology = super::super::least_squares::Topology::new(&mask);
        let n = topology.len();
        let weight = |k: usize, d: usize| [1.0 + ((k * 31 + d * 7) % 13) as f64, 0.5][d % 2];
        let second_weights: Vec<[f64; 2]> = (0..n).map(|k| [weight(k, 0), weight(k, 1)]).collect();
        let mut reused = topology.laplacian(&(0..n).map(|_| [1.0; 2]).collect::<Vec<_>>());
        let mut kept = Multigrid::new(&reused, 1e-10);
        let r: Vec<f64> = (0..n).map(|k| ((k * 7919) % 101) as f64 - 50.0).collect();
        let mut before = vec![0.0; n];
        kept.precondition(&reused, &r, &mut before);
        topology.reweight_laplacian(&mut reused, &second_weights);
        kept.reweight(&reused, 1e-10);
        let second = topology.laplacian(&second_weights);
        assert_eq!(reused.weights, second.weights);
        assert_eq!(reused.diag, second.diag);
        let mut fresh = Multigrid::new(&second, 1e-10);
        let (mut a, mut b) = (vec![f64::NAN; n], vec![0.0; n]);
        kept.precondition(&reused, &r, &mut a);
        fresh.precondition(&second, &r, &mut b);
        assert!(kept.levels.len() >= 2, "{} levels", kept.levels.len());
        assert_eq!(a, b);
        assert_ne!(a, before);
        let (mut ya, mut yb) = (vec![0.0; n], vec![0.0; n]);
        reused.apply(&r, &mut ya);
        second.apply(&r, &mut yb);
        assert_eq!(ya, yb);
    }

    /// The first pre-smoothing sweep from zero equals zeroing x and sweeping forward, bit for
    /// bit, whatever x held (NaN included), on a Laplacian with uneven weights and isolated
    /// nodes (whose stencils refer to themselves).
    #[test]
    fn the_sweep_from_zero_equals_a_forward_sweep_after_zeroing() {
        let mask = ndarray::Array2::from_shape_fn((30, 41), |(r, c)| {
            let (y, x) = (r as f64 - 15.0, c as f64 - 20.0);
            (x * x + y * y < 13.0 * 13.0 && c != 20) || (r % 7 == 3 && c == 39)
        });
        let topology =
            super::super::least_squares::Topology::with_isolated(&mask, |(_, c)| c == 39);
        let n = topology.len();
        assert!(
            topology
                .neighbours
                .iter()
                .any(|nb| nb.iter().all(|&j| j == NONE))
        );
        let weights: Vec<[f64; 2]> = (0..n)
            .map(|k| [0.25 + (k % 5) as f64, 1.0 + (k % 3) as f64 * 0.3])
            .collect();
        let a = topology.laplacian(&weights);
        let b: Vec<f64> = (0..n).map(|k| ((k * 7919) % 101) as f64 - 50.3).collect();
        let mut scratch = vec![0.0; n];
        let mut reference = vec![0.0; n];
        a.gauss_seidel(&b, &mut reference, true, &mut scratch);
        let mut from_zero = vec![f64::NAN; n];
        a.gauss_seidel_from_zero(&b, &mut from_zero, &mut scratch);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&from_zero), bits(&reference));
        assert!(reference.iter().all(|x| x.is_finite() && *x != 0.0));
    }

    /// After a forward sweep, the restriction from the even nodes alone equals the full
    /// restriction Pᵀ(b − A x) but for rounding (the odd nodes' residual is zero), and the
    /// residual it leaves out is that small while the even nodes' is not.
    #[test]
    fn the_even_restriction_equals_the_full_one_after_a_forward_sweep() {
        let mask = ndarray::Array2::from_shape_fn((37, 45), |(r, c)| {
            let (y, x) = (r as f64 - 18.0, c as f64 - 21.0);
            x * x + y * y < 17.0 * 17.0 && !(r == 18 && c > 10)
        });
        let topology = super::super::least_squares::Topology::new(&mask);
        let n = topology.len();
        let weights: Vec<[f64; 2]> = (0..n)
            .map(|k| [0.5 + (k % 7) as f64, 1.0 + (k % 4) as f64 * 0.25])
            .collect();
        let a = topology.laplacian(&weights);
        let level = a.coarsen(1e-10);
        let b: Vec<f64> = (0..n).map(|k| ((k * 7919) % 101) as f64 - 50.3).collect();
        let (mut x, mut res) = (vec![0.0; n], vec![0.0; n]);
        a.gauss_seidel_from_zero(&b, &mut x, &mut res);
        a.apply(&x, &mut res);
        let mut full = vec![0.0; level.a.len()];
        let (mut odd, mut even) = (0.0f64, 0.0f64);
        for (k, &p) in level.parent.iter().enumerate() {
            let r = b[k] - res[k];
            full[p as usize] += r;
            let (row, col) = a.cells[k];
            if (row + col) % 2 == 0 {
                even = even.max(r.abs());
            } else {
                odd = odd.max(r.abs());
            }
        }
        let mut from_even = vec![f64::NAN; level.a.len()];
        a.restrict_even_residual(&b, &x, &level.even_children, &mut from_even);
        let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(even > 0.1 * scale && odd < 1e-13 * scale, "{even} {odd}");
        for (p, (e, f)) in from_even.iter().zip(&full).enumerate() {
            assert!((e - f).abs() <= 1e-13 * scale, "aggregate {p}: {e} vs {f}");
        }
    }

    #[test]
    fn hierarchy_coarsens_and_the_v_cycle_is_symmetric_positive() {
        // An annulus plus a separate bar: holes and two components.
        let a = laplacian(70, 90, |r, c| {
            let (y, x) = (r as f64 - 35.0, c as f64 - 35.0);
            let d2 = x * x + y * y;
            (d2 < 30.0 * 30.0 && d2 > 8.0 * 8.0) || ((75..85).contains(&c) && r > 5)
        });
        let mut mg = Multigrid::new(&a, 1e-10);
        assert!(mg.levels.len() >= 3, "{} levels", mg.levels.len());
        assert!(mg.levels.last().is_some_and(|l| l.a.len() <= COARSEST_SIZE));
        let n = a.len();
        let u: Vec<f64> = (0..n).map(|k| ((k * 7919) % 101) as f64 - 50.0).collect();
        let v: Vec<f64> = (0..n).map(|k| ((k * 104_729) % 37) as f64 - 18.0).collect();
        let (mut bu, mut bv) = (vec![0.0; n], vec![0.0; n]);
        mg.precondition(&a, &u, &mut bu);
        mg.precondition(&a, &v, &mut bv);
        let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
        let (uv, vu) = (dot(&bu, &v), dot(&u, &bv));
        assert!(
            (uv - vu).abs() <= 1e-9 * uv.abs().max(vu.abs()),
            "{uv} vs {vu}"
        );
        assert!(dot(&bu, &u) > 0.0 && dot(&bv, &v) > 0.0);
    }
}
