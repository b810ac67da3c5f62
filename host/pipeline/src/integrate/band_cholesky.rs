//! Cholesky factorisation of a symmetric positive-definite band matrix, for the coarsest level of
//! the multigrid hierarchy ([`super::multigrid`]). A 4-neighbour grid operator numbered in
//! raster order couples a node only with nodes at most one grid row away, so it is a band matrix
//! whose half-bandwidth b is about one row of the coarse grid: the factorisation costs ≈ n·b²/2
//! and each solve ≈ 2·n·b multiply–adds instead of n³/3 and n² for a dense factor (Golub &
//! Van Loan, "Matrix Computations", 4th ed. 2013, §4.3.5 "band Cholesky" and §4.3.2 "band
//! triangular solves").

/// The lower-triangular band factor L of A = L Lᵀ.
#[derive(Debug, Clone)]
pub(crate) struct BandCholesky {
    /// Order of the matrix.
    n: usize,
    /// Half-bandwidth b: A[i][j] = 0 when |i − j| > b.
    bandwidth: usize,
    /// Row i of L from column i − b to column i, at `i·(b + 1) + (j + b − i)` (entries left of
    /// column 0 stay zero).
    factor: Vec<f64>,
}

impl BandCholesky {
    /// Factors the symmetric matrix of order `n` and half-bandwidth `bandwidth` whose lower
    /// triangle `lower` lists as (row, column ≤ row, value); entries not listed are zero and a
    /// repeated entry is summed. `None` when the matrix is not positive definite (or not
    /// finite), or an entry lies outside the order or the band.
    pub fn new(
        n: usize,
        bandwidth: usize,
        lower: impl IntoIterator<Item = (usize, usize, f64)>,
    ) -> Option<Self> {
        let width = bandwidth + 1;
        let mut factor = vec![0.0; n * width];
        for (i, j, value) in lower {
            if i >= n || j > i || i - j > bandwidth {
                return None;
            }
            factor[i * width + j + bandwidth - i] += value;
        }
        let at = |i: usize, j: usize| i * width + j + bandwidth - i;
        for i in 0..n {
            let first = i.saturating_sub(bandwidth);
            for j in first..=i {
                // L[i][j] = (A[i][j] − Σ_{m<j} L[i][m]·L[j][m]) / L[j][j]; both rows are zero
                // left of `first` (row j's band starts at or before it, row i's at it).
                let mut s = factor[at(i, j)];
                for m in first..j {
                    s -= factor[at(i, m)] * factor[at(j, m)];
                }
                if i == j {
                    if !(s > 0.0 && s.is_finite()) {
                        return None;
                    }
                    factor[at(i, i)] = s.sqrt();
                } else {
                    factor[at(i, j)] = s / factor[at(j, j)];
                }
            }
        }
        Some(Self {
            n,
            bandwidth,
            factor,
        })
    }

    /// Solves A x = b in place (`x` holds b on entry).
    pub fn solve_in_place(&self, x: &mut [f64]) {
        assert_eq!(x.len(), self.n, "a right-hand side of another order");
        let (b, width) = (self.bandwidth, self.bandwidth + 1);
        let at = |i: usize, j: usize| i * width + j + b - i;
        // L y = b, forwards.
        for i in 0..self.n {
            let first = i.saturating_sub(b);
            let mut s = x[i];
            for (m, &xm) in (first..i).zip(&x[first..i]) {
                s -= self.factor[at(i, m)] * xm;
            }
            x[i] = s / self.factor[at(i, i)];
        }
        // Lᵀ x = y, backwards.
        for i in (0..self.n).rev() {
            let last = (i + b + 1).min(self.n);
            let mut s = x[i];
            for (m, &xm) in (i + 1..last).zip(&x[i + 1..last]) {
                s -= self.factor[at(m, i)] * xm;
            }
            x[i] = s / self.factor[at(i, i)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// The shifted 5-point Laplacian of a `rows`×`cols` grid with uneven weights, dense.
    fn grid_matrix(rows: usize, cols: usize) -> DMatrix<f64> {
        let n = rows * cols;
        let mut a = DMatrix::zeros(n, n);
        for k in 0..n {
            let (r, c) = (k / cols, k % cols);
            let mut link = |j: usize, w: f64| {
                a[(k, j)] -= w;
                a[(j, k)] -= w;
                a[(k, k)] += w;
                a[(j, j)] += w;
            };
            if c + 1 < cols {
                link(k + 1, 1.0 + ((k * 7) % 5) as f64);
            }
            if r + 1 < rows {
                link(k + cols, 0.5 + ((k * 3) % 4) as f64);
            }
        }
        for k in 0..n {
            a[(k, k)] += 1e-3;
        }
        a
    }

    fn lower(a: &DMatrix<f64>) -> Vec<(usize, usize, f64)> {
        let n = a.nrows();
        (0..n)
            .flat_map(|i| (0..=i).map(move |j| (i, j)))
            .filter(|&(i, j)| a[(i, j)] != 0.0)
            .map(|(i, j)| (i, j, a[(i, j)]))
            .collect()
    }

    /// The band factor solves a grid operator as the dense Cholesky factor does.
    #[test]
    fn solves_a_grid_operator_like_the_dense_factor() {
        let (rows, cols) = (9, 13);
        let a = grid_matrix(rows, cols);
        let n = rows * cols;
        let band = BandCholesky::new(n, cols, lower(&a)).expect("positive definite");
        let b = DVector::from_fn(n, |k, _| ((k * 7919) % 101) as f64 - 50.0);
        let dense = a.clone().cholesky().expect("positive definite").solve(&b);
        let mut x = b.as_slice().to_vec();
        band.solve_in_place(&mut x);
        let worst = x
            .iter()
            .zip(dense.iter())
            .map(|(p, q)| (p - q).abs() / q.abs().max(1.0))
            .fold(0.0, f64::max);
        assert!(worst < 1e-10, "{worst}");
        // And A x = b to rounding.
        let residual = (&a * DVector::from_column_slice(&x) - &b).amax();
        assert!(residual < 1e-8 * b.amax(), "{residual}");
    }

    /// An indefinite matrix, an entry outside the band and one above the diagonal are refused.
    #[test]
    fn refuses_what_it_cannot_factor() {
        let mut a = grid_matrix(3, 4);
        a[(5, 5)] = -1.0;
        assert!(BandCholesky::new(12, 4, lower(&a)).is_none());
        assert!(BandCholesky::new(12, 4, [(11, 0, 1.0)]).is_none());
        assert!(BandCholesky::new(12, 4, [(2, 3, 1.0)]).is_none());
        assert!(BandCholesky::new(2, 1, [(0, 0, 1.0), (1, 1, f64::NAN)]).is_none());
    }
}
