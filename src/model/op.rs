//! Linear operators: a shape-aware `forward`/`adjoint` pair. Solvers are written once
//! against this trait; a new optic or shutter is a new operator. The loss over what a
//! capture measured (observations, clipped pixels, the ranks of a split problem) is
//! the data term's ([`crate::model::data::DataTerm`]), not the operator's.

use crate::model::conv::Conv2d;
use crate::model::shutter::ShutterWeights;

/// The structure of an operator `M A` with `A v = sum_k W[:, k] . crop(h * v_k)` on the
/// whole video grid of `conv` (no restriction of the unknowns): the convolution (its
/// PSF, video grid, padded FFT grid and offset), the shutter weights `W` and the
/// sensor mask `M`. What a solver needs to split `A` into a convolution, diagonal in
/// Fourier, and a per-pixel map (`crate::solve::optimize::admm_split`).
#[derive(Clone, Copy)]
pub struct ShutterConvolution<'a> {
    pub conv: &'a Conv2d,
    pub weights: &'a ShutterWeights,
    pub mask: Option<&'a [f32]>,
}

/// Upper bounds of `lambda_max(A^T A)` from the PSF and the shutter weights alone, to
/// check a stored Lipschitz constant without measuring it again. With `C` the cropped
/// convolution, `(C v)_i` its sensor row `i`, `w_ik` the weights, `S_i = sum_k |w_ik|`,
/// and a mask (entries in [0, 1]) that only lowers them:
///
/// - rows: sensor row `i` is `sum_p h_(a(i,p)) * v_p` over the video rows `p` (distinct
///   PSF rows `a`), so by Cauchy-Schwarz at each frequency of the row FFT and Parseval,
///   `||(C v)_i||^2 <= gamma ||v||^2` with `gamma = max_w sum_a |FFT(h_a)(w)|^2`
///   ([`Conv2d::row_gain_sq`]); and `(sum_k w_ik c_k)^2 <= S_i sum_k |w_ik| c_k^2`, so
///   `||A v||^2 <= gamma sum_k (sum_i S_i |w_ik|) ||v_k||^2`;
/// - whole: `||C|| <= sum |h|` (Young) and Cauchy-Schwarz over the frames give
///   `(sum |h|)^2 max_i sum_k w_ik^2`.
///
/// The smaller of the two is the bound. For one image seen by every frame
/// (`v_k = s`), the same steps give `min(gamma sum_i S_i^2, (sum |h|)^2 max_i S_i^2)`.
impl ShutterConvolution<'_> {
    /// `S_i = sum_k |w_ik|` per sensor row.
    fn row_sums(&self) -> Vec<f64> {
        let w = self.weights;
        let mut s = vec![0.0f64; w.rows()];
        for k in 0..w.frames() {
            for r in w.rows_of_frame(k) {
                for i in r.clone() {
                    s[i] += (w.get(i, k) as f64).abs();
                }
            }
        }
        s
    }

    /// An upper bound of `lambda_max(A^T A)` for the video operator.
    pub fn lambda_upper_bound(&self) -> f64 {
        let w = self.weights;
        let s = self.row_sums();
        let (mut per_frame, mut per_row_sq) = (0.0f64, vec![0.0f64; w.rows()]);
        for k in 0..w.frames() {
            let mut frame = 0.0f64;
            for r in w.rows_of_frame(k) {
                for i in r.clone() {
                    let v = (w.get(i, k) as f64).abs();
                    frame += s[i] * v;
                    per_row_sq[i] += v * v;
                }
            }
            per_frame = per_frame.max(frame);
        }
        let rows = self.conv.row_gain_sq() * per_frame;
        let whole = self.conv.psf_l1().powi(2) * per_row_sq.iter().cloned().fold(0.0, f64::max);
        rows.min(whole)
    }

    /// An upper bound of `lambda_max` of `s -> A (1 ⊗ s)`: one image in every frame.
    pub fn static_lambda_upper_bound(&self) -> f64 {
        let s = self.row_sums();
        let rows = self.conv.row_gain_sq() * s.iter().map(|v| v * v).sum::<f64>();
        let whole = self.conv.psf_l1().powi(2) * s.iter().map(|v| v * v).fold(0.0, f64::max);
        rows.min(whole)
    }
}

/// A linear map from a flat `input_len` vector to a flat `output_len` vector.
///
/// Implementations must satisfy `<A x, y> = <x, A^T y>` to float precision; the
/// [`adjoint_mismatch`] helper measures it.
pub trait Operator: Send + Sync {
    /// Shape of the input (e.g. `[frames, rows, cols]`).
    fn input_shape(&self) -> Vec<usize>;
    /// Shape of the output (e.g. `[rows, cols]`).
    fn output_shape(&self) -> Vec<usize>;
    /// `y = A x` (overwrites `y`).
    fn forward(&self, x: &[f32], y: &mut [f32]);
    /// `x = A^T y` (overwrites `x`).
    fn adjoint(&self, y: &[f32], x: &mut [f32]);

    /// The operator as a shutter-weighted convolution ([`ShutterConvolution`]), when it
    /// is exactly that; `None` (the default) for any other map.
    fn shutter_convolution(&self) -> Option<ShutterConvolution<'_>> {
        None
    }

    /// A cheap upper bound of the largest eigenvalue of `A^T A` from the operator's
    /// structure (the PSF and the shutter weights), against which a stored Lipschitz
    /// constant is checked; `None` when none is known. The default is a shutter
    /// convolution's ([`ShutterConvolution::lambda_upper_bound`]).
    fn lipschitz_upper_bound(&self) -> Option<f64> {
        self.shutter_convolution().map(|s| s.lambda_upper_bound())
    }

    /// `y = A (1 ⊗ s)` for a video operator: the data of the video whose every frame
    /// is the image `s`, by a form that does not build that video (a shutter
    /// convolution's is one convolution of `s`, [`crate::model::still`]). `false` (the
    /// default): the operator has none, and `y` is unspecified.
    fn forward_still(&self, _s: &[f32], _y: &mut [f32]) -> bool {
        false
    }

    /// `s = sum_k (A^T y)_k`, the adjoint of [`Operator::forward_still`]; `false` (the
    /// default) when the operator has no such form.
    fn adjoint_still(&self, _y: &[f32], _s: &mut [f32]) -> bool {
        false
    }

    fn input_len(&self) -> usize {
        self.input_shape().iter().product()
    }
    fn output_len(&self) -> usize {
        self.output_shape().iter().product()
    }
}

/// The largest finite entry of `A^T b`: the scale of the TV weight (a weight of this
/// order flattens the video) and of the Haar map's bias (`solve::prox::tv_dual::haar_strength`).
pub fn adjoint_peak<A: Operator + ?Sized>(op: &A, b: &[f32]) -> f32 {
    let mut atb = vec![0.0f32; op.input_len()];
    op.adjoint(b, &mut atb);
    atb.iter().fold(0.0f32, |m, &v| if v.is_finite() { m.max(v) } else { m })
}

/// A reference to an operator, and a shared one (one built for several problems), is
/// the operator.
macro_rules! forward_operator {
    ($($ty:ty),*) => {$(
        impl<T: Operator + ?Sized> Operator for $ty {
            fn input_shape(&self) -> Vec<usize> {
                (**self).input_shape()
            }
            fn output_shape(&self) -> Vec<usize> {
                (**self).output_shape()
            }
            fn forward(&self, x: &[f32], y: &mut [f32]) {
                (**self).forward(x, y)
            }
            fn adjoint(&self, y: &[f32], x: &mut [f32]) {
                (**self).adjoint(y, x)
            }
            fn shutter_convolution(&self) -> Option<ShutterConvolution<'_>> {
                (**self).shutter_convolution()
            }
            fn lipschitz_upper_bound(&self) -> Option<f64> {
                (**self).lipschitz_upper_bound()
            }
            fn forward_still(&self, s: &[f32], y: &mut [f32]) -> bool {
                (**self).forward_still(s, y)
            }
            fn adjoint_still(&self, y: &[f32], s: &mut [f32]) -> bool {
                (**self).adjoint_still(y, s)
            }
        }
    )*};
}
forward_operator!(&T, std::sync::Arc<T>);

/// Dot product accumulated in f64.
pub fn dot(a: &[f32], b: &[f32]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    // Pairwise-ish: f64 accumulation in chunks keeps long sums accurate.
    a.chunks(4096).zip(b.chunks(4096)).map(|(x, y)| x.iter().zip(y).map(|(&p, &q)| p as f64 * q as f64).sum::<f64>()).sum()
}

/// Relative mismatch `|<Ax,y> - <x,A^T y>| / (|<Ax,y>| + tiny)` for the given vectors.
pub fn adjoint_mismatch<A: Operator + ?Sized>(op: &A, x: &[f32], y: &[f32]) -> f64 {
    let mut ax = vec![0.0; op.output_len()];
    let mut aty = vec![0.0; op.input_len()];
    op.forward(x, &mut ax);
    op.adjoint(y, &mut aty);
    let lhs = dot(&ax, y);
    let rhs = dot(x, &aty);
    (lhs - rhs).abs() / (lhs.abs().max(rhs.abs()) + 1e-300)
}

/// Pseudo-random vector in [0, 1) (xorshift; deterministic, no dependency on rand's
/// algorithms so that cached results stay comparable).
pub fn pseudo_random(len: usize, seed: u64) -> Vec<f32> {
    pseudo_random_range(seed, 0..len)
}

/// Entries `range` of the sequence [`pseudo_random`] gives for `seed` (the values
/// before `range.start` are stepped over, not stored): a block of a long vector.
pub fn pseudo_random_range(seed: u64, range: std::ops::Range<usize>) -> Vec<f32> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    for _ in 0..range.start {
        next();
    }
    range.map(|_| (next() >> 40) as f32 / (1u64 << 24) as f32).collect()
}

/// A dense matrix as an operator (tests and small reference computations).
#[derive(Clone, Debug)]
pub struct Dense {
    pub rows: usize,
    pub cols: usize,
    /// Row-major.
    pub a: Vec<f32>,
}

impl Dense {
    /// Materialise any operator column by column (only for small problems).
    pub fn from_operator<A: Operator + ?Sized>(op: &A) -> Dense {
        let (n, m) = (op.input_len(), op.output_len());
        let mut a = vec![0.0; m * n];
        let mut e = vec![0.0; n];
        let mut col = vec![0.0; m];
        for j in 0..n {
            e[j] = 1.0;
            op.forward(&e, &mut col);
            for i in 0..m {
                a[i * n + j] = col[i];
            }
            e[j] = 0.0;
        }
        Dense { rows: m, cols: n, a }
    }
}

impl Dense {
    /// Largest eigenvalue of `A^T A`, by cyclic Jacobi rotations in f64: the dense
    /// reference for power iteration on small problems.
    pub fn gram_lambda_max(&self) -> f64 {
        let a = self;
        let n = a.cols;
        let mut s = vec![0.0f64; n * n];
        for i in 0..n {
            for j in 0..n {
                s[i * n + j] = (0..a.rows).map(|r| a.a[r * n + i] as f64 * a.a[r * n + j] as f64).sum();
            }
        }
        for _sweep in 0..60 {
            let off: f64 = (0..n).flat_map(|p| (0..n).filter(move |&q| q != p).map(move |q| (p, q))).map(|(p, q)| s[p * n + q].powi(2)).sum();
            if off < 1e-24 {
                break;
            }
            for p in 0..n {
                for q in p + 1..n {
                    let apq = s[p * n + q];
                    if apq.abs() < 1e-300 {
                        continue;
                    }
                    let theta = 0.5 * (s[q * n + q] - s[p * n + p]) / apq;
                    let t = if theta == 0.0 { 1.0 } else { theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt()) };
                    let c = 1.0 / (t * t + 1.0).sqrt();
                    let sn = t * c;
                    for k in 0..n {
                        let (skp, skq) = (s[k * n + p], s[k * n + q]);
                        s[k * n + p] = c * skp - sn * skq;
                        s[k * n + q] = sn * skp + c * skq;
                    }
                    for k in 0..n {
                        let (spk, sqk) = (s[p * n + k], s[q * n + k]);
                        s[p * n + k] = c * spk - sn * sqk;
                        s[q * n + k] = sn * spk + c * sqk;
                    }
                }
            }
        }
        (0..n).map(|i| s[i * n + i]).fold(f64::MIN, f64::max)
    }
}

impl Operator for Dense {
    fn input_shape(&self) -> Vec<usize> {
        vec![self.cols]
    }
    fn output_shape(&self) -> Vec<usize> {
        vec![self.rows]
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        for (i, yi) in y.iter_mut().enumerate() {
            *yi = dot(&self.a[i * self.cols..(i + 1) * self.cols], x) as f32;
        }
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        let mut acc = vec![0.0f64; self.cols];
        for (i, &yi) in y.iter().enumerate() {
            for (j, a) in acc.iter_mut().enumerate() {
                *a += self.a[i * self.cols + j] as f64 * yi as f64;
            }
        }
        for (xj, a) in x.iter_mut().zip(acc) {
            *xj = a as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dense_adjoint_is_exact() {
        let a = Dense { rows: 3, cols: 4, a: pseudo_random(12, 1) };
        let x = pseudo_random(4, 2);
        let y = pseudo_random(3, 3);
        assert!(adjoint_mismatch(&a, &x, &y) < 1e-6);
    }

    #[test]
    fn pseudo_random_is_in_unit_interval_and_varied() {
        let v = pseudo_random(1000, 7);
        assert!(v.iter().all(|&x| (0.0..1.0).contains(&x)));
        let mean: f32 = v.iter().sum::<f32>() / 1000.0;
        assert!((mean - 0.5).abs() < 0.05, "{mean}");
    }
}
