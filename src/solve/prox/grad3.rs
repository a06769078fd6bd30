//! Forward differences on a `(frames, rows, cols)` volume, one axis at a time, and
//! their adjoints: the linear pieces the ADMM splitting and the dual TV prox need.
//! Differences have no wrap-around; the difference at the last sample of an axis is 0.

/// Length and stride of `axis` (0 = t, 1 = y, 2 = x) in a `(k, m, n)` volume.
#[inline]
pub fn axis_geometry(shape: (usize, usize, usize), axis: usize) -> (usize, usize) {
    let (k, m, n) = shape;
    match axis {
        0 => (k, m * n),
        1 => (m, n),
        _ => (n, 1),
    }
}

/// `d[i] = v[i + s] - v[i]` where the next sample exists along `axis`, else 0.
pub fn diff(shape: (usize, usize, usize), axis: usize, v: &[f32], d: &mut [f32]) {
    let (len, stride) = axis_geometry(shape, axis);
    let block = len * stride;
    for (vb, db) in v.chunks(block).zip(d.chunks_mut(block)) {
        for c in 0..len {
            let o = &mut db[c * stride..(c + 1) * stride];
            if c + 1 < len {
                let (a, b) = (&vb[c * stride..(c + 1) * stride], &vb[(c + 1) * stride..(c + 2) * stride]);
                for ((o, &x), &y) in o.iter_mut().zip(a).zip(b) {
                    *o = y - x;
                }
            } else {
                o.fill(0.0);
            }
        }
    }
}

/// Adds `scale * D^T p` to `out`: `(D^T p)[i] = p[i - s] (if c > 0) - p[i] (if c < len-1)`.
pub fn diff_adjoint_add(shape: (usize, usize, usize), axis: usize, p: &[f32], scale: f32, out: &mut [f32]) {
    let (len, stride) = axis_geometry(shape, axis);
    let block = len * stride;
    for (pb, ob) in p.chunks(block).zip(out.chunks_mut(block)) {
        for c in 0..len {
            let o = &mut ob[c * stride..(c + 1) * stride];
            if c > 0 {
                for (o, &x) in o.iter_mut().zip(&pb[(c - 1) * stride..c * stride]) {
                    *o += scale * x;
                }
            }
            if c + 1 < len {
                for (o, &x) in o.iter_mut().zip(&pb[c * stride..(c + 1) * stride]) {
                    *o -= scale * x;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::{dot, pseudo_random};

    #[test]
    fn adjoint_of_each_axis_is_exact() {
        let shape = (3, 4, 5);
        let v = pseudo_random(60, 1);
        let p = pseudo_random(60, 2);
        for axis in 0..3 {
            let mut d = vec![0.0; 60];
            diff(shape, axis, &v, &mut d);
            let mut dtp = vec![0.0; 60];
            diff_adjoint_add(shape, axis, &p, 1.0, &mut dtp);
            // The last sample of each line has no difference: p there is unused.
            let (len, stride) = axis_geometry(shape, axis);
            let pm: Vec<f32> = p.iter().enumerate().map(|(i, &x)| if (i / stride) % len + 1 < len { x } else { 0.0 }).collect();
            let (a, b) = (dot(&d, &pm), dot(&v, &dtp));
            assert!((a - b).abs() < 1e-5 * a.abs().max(1.0), "axis {axis}: {a} vs {b}");
        }
    }
}
