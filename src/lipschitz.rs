//! The step size of gradient methods: the largest eigenvalue of `A^T A`, measured by
//! power iteration, and cached on disk per operator fingerprint (PSF + timing + grid),
//! because it costs as much as a few dozen solver iterations.

use crate::op::{dot, pseudo_random, Operator};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

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
    let mut x: Vec<f32> = pseudo_random(op.input_len(), seed).iter().map(|v| v + 0.5).collect();
    let mut ax = vec![0.0f32; op.output_len()];
    let mut atax = vec![0.0f32; op.input_len()];
    let mut lambda = 0.0f64;
    let mut rel = f64::INFINITY;
    let mut it = 0;
    while it < max_iters {
        it += 1;
        let nx = dot(&x, &x).sqrt();
        if nx == 0.0 || !nx.is_finite() {
            return Eigen { lambda_max: 0.0, iterations: it, rel_change: 0.0 };
        }
        let inv = (1.0 / nx) as f32;
        x.iter_mut().for_each(|v| *v *= inv);
        op.forward(&x, &mut ax);
        op.adjoint(&ax, &mut atax);
        // Rayleigh quotient of the unit vector x: ||A x||^2.
        let new = dot(&ax, &ax);
        rel = ((new - lambda) / new.max(1e-300)).abs();
        lambda = new;
        std::mem::swap(&mut x, &mut atax);
        if rel < tol {
            break;
        }
    }
    Eigen { lambda_max: lambda, iterations: it, rel_change: rel }
}

/// Safety margin applied to the measured eigenvalue to obtain the step's Lipschitz
/// constant: power iteration approaches the eigenvalue from below.
pub const LIPSCHITZ_MARGIN: f64 = 1.01;

/// 64-bit FNV-1a over byte slices: a stable fingerprint for cache keys.
#[derive(Clone, Copy)]
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

/// On-disk cache of measured eigenvalues, one small JSON file per fingerprint.
pub struct LipschitzCache {
    dir: Option<PathBuf>,
}

impl LipschitzCache {
    /// `$ROLLCAM_CACHE_DIR`, else `$XDG_CACHE_HOME/rollcam`, else `~/.cache/rollcam`;
    /// `ROLLCAM_CACHE_DIR=off` disables caching.
    pub fn default_location() -> Self {
        let dir = match std::env::var_os("ROLLCAM_CACHE_DIR") {
            Some(v) if v == "off" => None,
            Some(v) => Some(PathBuf::from(v)),
            None => std::env::var_os("XDG_CACHE_HOME")
                .map(|x| PathBuf::from(x).join("rollcam"))
                .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("rollcam"))),
        };
        LipschitzCache { dir: dir.map(|d| d.join("lipschitz")) }
    }

    pub fn at(dir: &Path) -> Self {
        LipschitzCache { dir: Some(dir.to_path_buf()) }
    }

    pub fn disabled() -> Self {
        LipschitzCache { dir: None }
    }

    /// The cached eigenvalue for `key`, or measure it (and store it).
    pub fn get_or_measure<A: Operator + ?Sized>(&self, key: Fingerprint, op: &A) -> (Eigen, bool) {
        let path = self.dir.as_ref().map(|d| d.join(format!("{}.json", key.hex())));
        if let Some(p) = &path {
            if let Ok(text) = std::fs::read_to_string(p) {
                if let Ok(e) = serde_json::from_str::<Eigen>(&text) {
                    if e.lambda_max.is_finite() && e.lambda_max > 0.0 {
                        tracing::debug!(path = %p.display(), lambda = e.lambda_max, "Lipschitz constant from cache");
                        return (e, true);
                    }
                }
            }
        }
        let e = power_iteration(op, 300, 1e-5, 0x5eed);
        tracing::info!(lambda = e.lambda_max, iterations = e.iterations, "measured Lipschitz constant by power iteration");
        if let Some(p) = &path {
            let write = || -> std::io::Result<()> {
                std::fs::create_dir_all(p.parent().unwrap())?;
                let tmp = p.with_extension(format!("tmp{}", std::process::id()));
                std::fs::write(&tmp, serde_json::to_string(&e).unwrap())?;
                std::fs::rename(&tmp, p)
            };
            if let Err(err) = write() {
                tracing::warn!(path = %p.display(), %err, "could not cache the Lipschitz constant");
            }
        }
        (e, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::op::Dense;

    #[test]
    fn power_iteration_matches_dense_eigenvalue() {
        let a = Dense { rows: 9, cols: 7, a: pseudo_random(63, 4) };
        let e = power_iteration(&a, 1000, 1e-10, 1);
        let exact = a.gram_lambda_max();
        assert!((e.lambda_max - exact).abs() / exact < 1e-5, "{} vs {exact}", e.lambda_max);
    }

    #[test]
    fn cache_returns_the_stored_value() {
        let dir = tempfile::tempdir().unwrap();
        let cache = LipschitzCache::at(dir.path());
        let a = Dense { rows: 4, cols: 3, a: pseudo_random(12, 8) };
        let key = Fingerprint::default().f32s(&a.a);
        let (e1, hit1) = cache.get_or_measure(key, &a);
        let (e2, hit2) = cache.get_or_measure(key, &a);
        assert!(!hit1 && hit2);
        assert_eq!(e1, e2);
        let other = Fingerprint::default().f32s(&a.a).usize(1);
        assert_ne!(other.hex(), key.hex());
    }
}
