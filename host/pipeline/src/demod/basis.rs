//! Orthonormal basis of the per-pixel least-squares model (the matched filter).
//!
//! The model of one pixel over F frames is `r = T·c + noise` with T = [1, t_0, …, t_{N−1}]
//! (F×K, K = N+1: background and one received waveform per LED, see [`super::waveform`]).
//! A modified Gram–Schmidt QR, T = QᵀR with Q K×F orthonormal rows, turns the least-squares
//! solution into `c = R⁻¹·(Q·r)` and the residual into `|r|² − |Q·r|²`, so a pixel only needs
//! K+1 running sums over the frames (streaming, no per-pixel matrix work).

/// The QR factors of the template matrix of one row band.
#[derive(Debug, Clone)]
pub struct TemplateBasis {
    /// Q: K rows of F values, orthonormal (a row is zero where T was rank deficient).
    pub rows: Vec<Vec<f64>>,
    /// R⁻¹ (K×K, upper triangular, row-major), zero where T was rank deficient.
    pub r_inverse: Vec<f64>,
    /// K: number of model columns.
    pub columns: usize,
}

impl TemplateBasis {
    /// Factors the column-major template `columns[k][j]` (K columns of F frames).
    pub fn new(columns: &[Vec<f64>]) -> Self {
        let k_count = columns.len();
        let mut q: Vec<Vec<f64>> = Vec::with_capacity(k_count);
        let mut r = vec![0.0f64; k_count * k_count];
        for (k, column) in columns.iter().enumerate() {
            let scale = column.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
            let mut v = column.clone();
            for (l, ql) in q.iter().enumerate() {
                let d: f64 = ql.iter().zip(&v).map(|(a, b)| a * b).sum();
                r[l * k_count + k] = d;
                for (vi, qi) in v.iter_mut().zip(ql) {
                    *vi -= d * qi;
                }
            }
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 1e-7 * scale {
                r[k * k_count + k] = norm;
                v.iter_mut().for_each(|x| *x /= norm);
            } else {
                v.iter_mut().for_each(|x| *x = 0.0);
            }
            q.push(v);
        }
        let r_inverse = upper_inverse(&r, k_count);
        Self {
            rows: q,
            r_inverse,
            columns: k_count,
        }
    }

    /// Model coefficients c = R⁻¹·b from the projections b = Q·r (writes `out`, K values).
    pub fn coefficients(&self, projections: &[f64], out: &mut [f64]) {
        let k = self.columns;
        for (row, value) in out.iter_mut().enumerate().take(k) {
            *value = (row..k)
                .map(|col| self.r_inverse[row * k + col] * projections[col])
                .sum();
        }
    }

    /// Variance factor of coefficient `k`: var(c_k) = σ² · (R⁻¹R⁻ᵀ)_kk.
    pub fn variance_factor(&self, k: usize) -> f64 {
        let n = self.columns;
        (k..n).map(|col| self.r_inverse[k * n + col].powi(2)).sum()
    }
}

/// Inverse of an upper-triangular K×K matrix (row-major); a zero diagonal gives a zero row.
fn upper_inverse(r: &[f64], k: usize) -> Vec<f64> {
    let mut inv = vec![0.0f64; k * k];
    for col in 0..k {
        for row in (0..=col).rev() {
            let diag = r[row * k + row];
            if diag == 0.0 {
                continue;
            }
            let identity = if row == col { 1.0 } else { 0.0 };
            let sum: f64 = (row + 1..=col)
                .map(|m| r[row * k + m] * inv[m * k + col])
                .sum();
            inv[row * k + col] = (identity - sum) / diag;
        }
    }
    inv
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_exact_coefficients() {
        let f = 20;
        let cols: Vec<Vec<f64>> = vec![
            vec![1.0; f],
            (0..f).map(|j| (j as f64 * 0.7).sin()).collect(),
            (0..f).map(|j| (j as f64 * 0.3).cos() + 0.2).collect(),
        ];
        let truth = [0.4, 1.5, -0.25];
        let r: Vec<f64> = (0..f)
            .map(|j| (0..3).map(|k| truth[k] * cols[k][j]).sum())
            .collect();
        let basis = TemplateBasis::new(&cols);
        let b: Vec<f64> = basis
            .rows
            .iter()
            .map(|q| q.iter().zip(&r).map(|(a, b)| a * b).sum())
            .collect();
        let mut c = [0.0; 3];
        basis.coefficients(&b, &mut c);
        for k in 0..3 {
            assert!((c[k] - truth[k]).abs() < 1e-5, "{c:?}");
        }
    }
}
