//! The step size of gradient methods: the largest eigenvalue of `A^T A`, measured by
//! power iteration, and cached on disk per operator fingerprint (PSF + timing + grid),
//! because it costs as much as a few dozen solver iterations.

use crate::model::op::{dot, pseudo_random_range, Operator};
use crate::model::ranks::Partition;
use serde::{Deserialize, Serialize};

/// Result of a power iteration.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Eigen {
    /// Estimate of the largest eigenvalue of A^T A (a lower bound that converges).
    pub lambda_max: f64,
    pub iterations: usize,
    /// Relative change of the estimate at the last iteration.
    pub rel_change: f64,
}

/// Power iteration on `A^T A` from a fixed pseudo-random start, until the Rayleigh
/// quotient changes by less than `tol` (relative) or `max_iters` is reached.
pub fn power_iteration<A: Operator + ?Sized>(op: &A, max_iters: usize, tol: f64, seed: u64) -> Eigen {
    power_iteration_from(op, Partition::ONE, power_start(op.input_len(), seed, 0..op.input_len()), max_iters, tol)
}

/// Entries `range` of the start vector of [`power_iteration`] for an input of `len`
/// values: a rank's block of the whole problem's start, so that a split problem
/// iterates on the same vector as the whole one.
pub fn power_start(len: usize, seed: u64, range: std::ops::Range<usize>) -> Vec<f32> {
    assert!(range.end <= len);
    pseudo_random_range(seed, range).into_iter().map(|v| v + 0.5).collect()
}

/// Power iteration from `x` (of the operator's input); the norms are taken over
/// `part` (the ranks of a split problem, [`crate::model::split::Split::partition`]), so
/// a rank's block operator measures the whole problem's eigenvalue, the same on every
/// rank.
pub fn power_iteration_from<A: Operator + ?Sized>(op: &A, part: Partition, x: Vec<f32>, max_iters: usize, tol: f64) -> Eigen {
    let mut x = x;
    assert_eq!(x.len(), op.input_len());
    let mut ax = vec![0.0f32; op.output_len()];
    let mut atax = vec![0.0f32; op.input_len()];
    let mut lambda = 0.0f64;
    let mut rel = f64::INFINITY;
    let mut it = 0;
    while it < max_iters {
        it += 1;
        let mut sq = [dot(&x, &x)];
        part.ranks.sum_f64(&mut sq);
        let nx = sq[0].sqrt();
        if nx == 0.0 || !nx.is_finite() {
            return Eigen { lambda_max: 0.0, iterations: it, rel_change: 0.0 };
        }
        let inv = (1.0 / nx) as f32;
        x.iter_mut().for_each(|v| *v *= inv);
        op.forward(&x, &mut ax);
        op.adjoint(&ax, &mut atax);
        // Rayleigh quotient of the unit vector x: ||A x||^2.
        let new = part.output_norm_sq(&ax);
        rel = ((new - lambda) / new.max(1e-300)).abs();
        lambda = new;
        std::mem::swap(&mut x, &mut atax);
        if rel < tol {
            break;
        }
    }
    Eigen { lambda_max: lambda, iterations: it, rel_change: rel }
}

/// The seed of the measurement's start vector ([`power_start`]).
pub const MEASURE_SEED: u64 = 0x5eed;

/// Safety margin applied to the measured eigenvalue to obtain the step's Lipschitz
/// constant: power iteration approaches the eigenvalue from below.
pub const LIPSCHITZ_MARGIN: f64 = 1.01;

/// A solve's step: the Lipschitz constant (with [`LIPSCHITZ_MARGIN`]) and whether it
/// came from the store (a stored constant that ends in a non-finite solve is measured
/// again).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lipschitz {
    pub value: f64,
    pub cached: bool,
}

impl Lipschitz {
    /// A constant measured now.
    pub fn measured(value: f64) -> Lipschitz {
        Lipschitz { value, cached: false }
    }
}

/// 64-bit FNV-1a over byte slices: a stable fingerprint for cache keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fingerprint(u64);

impl Default for Fingerprint {
    fn default() -> Self {
        Fingerprint(0xcbf2_9ce4_8422_2325)
    }
}

impl Fingerprint {
    pub fn bytes(mut self, data: &[u8]) -> Self {
        for &b in data {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
        self
    }
    pub fn f32s(self, data: &[f32]) -> Self {
        let mut s = self;
        for v in data {
            s = s.bytes(&v.to_le_bytes());
        }
        s
    }
    pub fn usize(self, v: usize) -> Self {
        self.bytes(&(v as u64).to_le_bytes())
    }
    pub fn hex(self) -> String {
        format!("{:016x}", self.0)
    }
}

/// Where measured eigenvalues are kept between runs, keyed by the operator's
/// [`Fingerprint`]. The solver layer measures; a store (the file cache of
/// `crate::io::cache`, or [`NoStore`]) only remembers.
pub trait EigenStore: Sync {
    /// The stored eigenvalue for `key`, if any.
    fn load(&self, key: &Fingerprint) -> Option<Eigen>;
    /// Remember `e` for `key` (failures are the store's to report).
    fn store(&self, key: &Fingerprint, e: &Eigen);

    /// The stored eigenvalue for `key` when it is plausible for `op` (see
    /// [`plausible`]), or measure it by power iteration and store it (replacing the
    /// stored one); the flag says whether it came from the store.
    fn get_or_measure(&self, key: Fingerprint, op: &dyn Operator) -> (Eigen, bool) {
        if let Some(e) = self.load(&key) {
            match plausible(&e, op) {
                Ok(()) => {
                    tracing::debug!(key = %key.hex(), lambda = e.lambda_max, "Lipschitz constant from cache");
                    return (e, true);
                }
                Err(why) => tracing::warn!(key = %key.hex(), lambda = e.lambda_max, "stored Lipschitz constant ignored and measured again: {why}"),
            }
        }
        (self.measure(key, op), false)
    }

    /// Measure by power iteration and store it (replacing what was stored).
    fn measure(&self, key: Fingerprint, op: &dyn Operator) -> Eigen {
        let e = power_iteration(op, 300, 1e-5, MEASURE_SEED);
        tracing::info!(lambda = e.lambda_max, iterations = e.iterations, "measured Lipschitz constant by power iteration");
        self.store(&key, &e);
        e
    }
}

/// Power iterations from the measurement's start that give the lower bound a stored
/// constant is checked against: a few solver iterations' cost, far less than measuring.
pub const CHECK_ITERATIONS: usize = 4;

/// Relative slack of the checks of a stored constant (f32 arithmetic, other thread
/// counts).
const CHECK_SLACK: f64 = 1e-3;

/// The range a correct `lambda_max` of `op` lies in: at least the Rayleigh quotient
/// after [`CHECK_ITERATIONS`] power iterations from the measurement's start (the
/// measurement's own sequence, which only rises), at most the operator's bound from
/// the PSF and the shutter weights ([`Operator::lipschitz_upper_bound`]) when it has
/// one.
pub fn lambda_range(op: &dyn Operator) -> (f64, Option<f64>) {
    let lower = power_iteration(op, CHECK_ITERATIONS, 0.0, MEASURE_SEED).lambda_max;
    (lower, op.lipschitz_upper_bound())
}

/// Whether a stored `lambda_max` can be right for `op`: finite and positive and inside
/// [`lambda_range`] (with a relative slack of 1e-3). A corrupt or mistaken cache entry
/// (10 times too large: steps 10 times too short; 10 times too small: a diverging
/// solve) fails it.
pub fn plausible(e: &Eigen, op: &dyn Operator) -> Result<(), String> {
    let l = e.lambda_max;
    if !(l.is_finite() && l > 0.0) {
        return Err(format!("{l} is not a positive number"));
    }
    let (lower, upper) = lambda_range(op);
    check_range(l, lower, upper)
}

/// `l` against the range `[lower, upper]` of [`lambda_range`], with the slack.
pub fn check_range(l: f64, lower: f64, upper: Option<f64>) -> Result<(), String> {
    if let Some(u) = upper {
        if l > u * (1.0 + CHECK_SLACK) {
            return Err(format!("{l:.4e} is above the bound {u:.4e} from the PSF and the shutter weights"));
        }
    }
    if l < lower * (1.0 - CHECK_SLACK) {
        return Err(format!("{l:.4e} is below {lower:.4e}, what {CHECK_ITERATIONS} power iterations already show"));
    }
    Ok(())
}

/// A store that remembers nothing: every solve measures.
pub struct NoStore;

impl EigenStore for NoStore {
    fn load(&self, _: &Fingerprint) -> Option<Eigen> {
        None
    }
    fn store(&self, _: &Fingerprint, _: &Eigen) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::{pseudo_random, Dense};

    #[test]
    fn a_block_of_the_start_is_the_whole_starts_block() {
        let whole = power_start(1000, 0x5eed, 0..1000);
        assert_eq!(power_start(1000, 0x5eed, 300..650), whole[300..650].to_vec());
        assert_eq!(power_start(1000, 0x5eed, 999..1000), whole[999..].to_vec());
    }

    #[test]
    fn power_iteration_matches_dense_eigenvalue() {
        let a = Dense { rows: 9, cols: 7, a: pseudo_random(63, 4) };
        let e = power_iteration(&a, 1000, 1e-10, 1);
        let exact = a.gram_lambda_max();
        assert!((e.lambda_max - exact).abs() / exact < 1e-5, "{} vs {exact}", e.lambda_max);
    }
}
