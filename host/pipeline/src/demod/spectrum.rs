//! The signal space of a window: leading eigenvectors of the pixel sample's Gram matrix.
//!
//! With X the sample (pixels × F, centred) and G = XᵀX, the noise-free part of X is A·Tᵀ (A the
//! pixels' on-levels A_i, T the F × N received waveforms u_i of
//! docs/maths/demodulation.md#the-received-signal), so the signal lives in
//! an N-dimensional subspace of R^F (a few more with a rolling shutter, whose rows see shifted
//! waveforms) and white noise adds the same energy σ²_G = Σ_p σ_p² to every direction. The
//! leading eigenpairs are found by randomised subspace iteration (Halko, Martinsson & Tropp,
//! "Finding structure with randomness", SIAM Review 2011, Alg. 4.4) with a fixed seed, so a
//! decode is deterministic; σ²_G is the mean of the trailing eigenvalues (the trace minus the
//! leading ones), which only noise reaches, over the directions left after the constant and
//! any nuisance components projected out of the sample (\[`super::nuisance`\]).

use nalgebra::{DMatrix, SymmetricEigen};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Extra random directions of the subspace iteration.
const OVERSAMPLING: usize = 8;
/// Power iterations of the subspace iteration.
const POWER_ITERATIONS: usize = 3;
/// An eigenvalue above this multiple of σ²_G counts as signal.
const SIGNAL_FACTOR: f64 = 2.0;

/// Leading eigenpairs of a window's Gram matrix, computed once and shared by every LED count
/// asked of the window (the LED-count check's and the decode's).
#[derive(Debug, Clone)]
pub struct Spectrum {
    /// Eigenvectors (F × k, columns) of the `values`, descending.
    vectors: DMatrix<f64>,
    /// The leading eigenvalues, descending.
    values: Vec<f64>,
    /// tr G: the sample's total energy.
    trace: f64,
    /// F.
    frames: usize,
    /// Directions projected out of the sample before G was formed (the room's nuisance
    /// components, [`super::nuisance`]): they hold neither signal nor noise.
    removed: usize,
}

impl Spectrum {
    /// Enough leading eigenpairs of the F × F Gram matrix of a centred sample for up to
    /// `leds` LEDs.
    pub fn new(gram: &DMatrix<f64>, leds: usize) -> Self {
        Self::projected(gram, leds, 0)
    }

    /// [`Spectrum::new`] of a sample with `removed` directions projected out (beyond the
    /// constant): σ²_G is then the trailing energy over the directions left.
    pub fn projected(gram: &DMatrix<f64>, leds: usize, removed: usize) -> Self {
        let frames = gram.nrows();
        let (values, vectors) = leading_eigenpairs(gram, leading_count(frames, leds));
        Self {
            vectors,
            values,
            trace: gram.trace(),
            frames,
            removed,
        }
    }

    /// The LED count the decomposition serves.
    fn serves(&self, leds: usize) -> bool {
        self.values.len() >= leading_count(self.frames, leds)
    }
}

/// Directions beyond the constant (removed by centring) that may hold the signal of `leds`
/// LEDs in a window of `frames`, leaving at least a quarter of the window (and two
/// directions) to measure the noise on.
fn leading_count(frames: usize, leds: usize) -> usize {
    let noise_dims = ((frames.saturating_sub(1)) / 4).max(2);
    (3 * leds + 2)
        .min(frames.saturating_sub(1 + noise_dims))
        .max(1)
}

/// Leading eigenpairs of the Gram matrix and the noise energy per dimension.
#[derive(Debug, Clone)]
pub struct SignalSpace {
    /// Eigenvectors (F × k, columns) of the `values`, descending.
    pub vectors: DMatrix<f64>,
    /// The leading eigenvalues, descending.
    pub values: Vec<f64>,
    /// σ²_G: noise energy per direction, summed over the sample's pixels.
    pub noise: f64,
    /// Directions that carry signal (at least the LED count, when the window allows).
    pub rank: usize,
}

impl SignalSpace {
    /// Analyses the F × F Gram matrix of a centred sample for `leds` LEDs.
    pub fn new(gram: &DMatrix<f64>, leds: usize) -> Self {
        Self::cut(&Spectrum::new(gram, leds), leds)
    }

    /// The space for `leds` LEDs from a decomposition of `gram` (recomputed when `spectrum`
    /// holds too few eigenpairs for that many LEDs).
    pub fn from_spectrum(spectrum: &Spectrum, gram: &DMatrix<f64>, leds: usize) -> Self {
        if spectrum.serves(leds) {
            Self::cut(spectrum, leds)
        } else {
            Self::cut(&Spectrum::projected(gram, leds, spectrum.removed), leds)
        }
    }

    /// The space for `leds` LEDs cut from the leading eigenpairs in `spectrum`.
    fn cut(spectrum: &Spectrum, leds: usize) -> Self {
        let f = spectrum.frames;
        let leading = leading_count(f, leds).min(spectrum.values.len());
        let values = spectrum.values[..leading].to_vec();
        let vectors = spectrum.vectors.columns(0, leading).into_owned();
        let captured: f64 = values.iter().sum();
        let rest = f.saturating_sub(1 + leading + spectrum.removed).max(1) as f64;
        let noise = ((spectrum.trace - captured) / rest).max(f64::MIN_POSITIVE);
        let significant = values
            .iter()
            .filter(|&&v| v > SIGNAL_FACTOR * noise)
            .count();
        let rank = significant.max(leds.min(leading)).min(vectors.ncols());
        Self {
            vectors,
            values,
            noise,
            rank,
        }
    }

    /// The signal directions (F × rank).
    pub fn basis(&self) -> nalgebra::DMatrixView<'_, f64> {
        self.vectors.columns(0, self.rank)
    }

    /// The leading directions, each scaled by the square root of its eigenvalue: B = V·Λ^½,
    /// so that |Bᵀt|² = tᵀ·V·Λ·Vᵀ·t is the energy the sample holds along t (the Gram
    /// quadratic form tᵀGt restricted to the leading directions).
    pub fn energy_basis(&self) -> DMatrix<f64> {
        let mut b = self.vectors.clone();
        for (mut column, &value) in b.column_iter_mut().zip(&self.values) {
            column *= value.max(0.0).sqrt();
        }
        b
    }
}

/// The `count` leading eigenpairs of a symmetric positive semi-definite matrix, descending;
/// none for an empty matrix (a window of no frames) or `count` = 0.
pub fn leading_eigenpairs(matrix: &DMatrix<f64>, count: usize) -> (Vec<f64>, DMatrix<f64>) {
    let n = matrix.nrows();
    if n == 0 || count == 0 {
        return (Vec::new(), DMatrix::zeros(n, 0));
    }
    let width = (count + OVERSAMPLING).min(n);
    let (values, vectors) = if width >= n {
        let eigen = SymmetricEigen::new(matrix.clone());
        (eigen.eigenvalues, eigen.eigenvectors)
    } else {
        let mut rng = ChaCha8Rng::seed_from_u64(0x5eed);
        let omega = DMatrix::from_fn(n, width, |_, _| StandardNormal.sample(&mut rng));
        let mut q = (matrix * omega).qr().q();
        for _ in 0..POWER_ITERATIONS {
            q = (matrix * &q).qr().q();
        }
        let small = q.transpose() * matrix * &q;
        let eigen = SymmetricEigen::new(small);
        (eigen.eigenvalues, q * eigen.eigenvectors)
    };
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    order.truncate(count.min(order.len()));
    let sorted = DMatrix::from_fn(n, order.len(), |r, c| vectors[(r, order[c])]);
    (order.iter().map(|&k| values[k].max(0.0)).collect(), sorted)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_a_planted_subspace_and_the_noise_level() {
        // G = 50·v1v1ᵀ + 20·v2v2ᵀ + 0.5·(I − 11ᵀ/F) on F = 40.
        let f = 40;
        // v1, v2 centred (orthogonal to the constant), so they are exact eigenvectors.
        let ones = DMatrix::from_element(f, 1, 1.0 / (f as f64).sqrt());
        let centre = |v: DMatrix<f64>| &v - &ones * (ones.transpose() * &v)[(0, 0)];
        let v1 = centre(DMatrix::from_fn(f, 1, |j, _| ((j as f64) * 0.7).sin()));
        let v1 = &v1 / v1.norm();
        let v2 = centre(DMatrix::from_fn(f, 1, |j, _| ((j as f64) * 1.9).cos()));
        let v2 = &v2 - &v1 * (v1.transpose() * &v2)[(0, 0)];
        let v2 = &v2 / v2.norm();
        let gram = &v1 * v1.transpose() * 50.0
            + &v2 * v2.transpose() * 20.0
            + (DMatrix::identity(f, f) - &ones * ones.transpose()) * 0.5;
        let space = SignalSpace::new(&gram, 2);
        assert!((space.values[0] - 50.5).abs() < 1e-6, "{:?}", space.values);
        assert!((space.values[1] - 20.5).abs() < 1e-6, "{:?}", space.values);
        assert_eq!(space.rank, 2);
        assert!((space.noise - 0.5).abs() < 1e-6, "{}", space.noise);
        let overlap = (space.basis().transpose() * &v1).norm();
        assert!((overlap - 1.0).abs() < 1e-9);
    }

    #[test]
    fn directions_projected_out_hold_no_noise() {
        // Noise 0.5 per direction with k = 6 further directions projected out of the sample:
        // σ²_G is taken over the directions left, so it stays 0.5.
        let f = 40;
        let ones = DMatrix::from_element(f, 1, 1.0 / (f as f64).sqrt());
        let mut removed = DMatrix::zeros(f, 0);
        for k in 0..6 {
            let mut v = DMatrix::from_fn(f, 1, |j, _| ((j * (k + 2)) as f64 * 0.37).sin());
            v -= &ones * (ones.transpose() * &v)[(0, 0)];
            for c in removed.column_iter() {
                let d = (c.transpose() * &v)[(0, 0)];
                v -= c * d;
            }
            let v = &v / v.norm();
            removed = removed.insert_column(k, 0.0);
            removed.set_column(k, &v.column(0));
        }
        let keep =
            DMatrix::identity(f, f) - &ones * ones.transpose() - &removed * removed.transpose();
        let gram = &keep * 0.5;
        let space = SignalSpace::from_spectrum(&Spectrum::projected(&gram, 2, 6), &gram, 2);
        assert!((space.noise - 0.5).abs() < 1e-6, "{}", space.noise);
        let naive = SignalSpace::new(&gram, 2);
        assert!(naive.noise < 0.47, "{}", naive.noise);
    }
}
