//! Reading a ground-truth video (`--truth`): a stack as [`super::read_stack`] reads it,
//! refused when any value is NaN or infinite (an error against such a truth is
//! meaningless: "PSNR inf dB").

use super::error::IoError;
use ndarray::Array4;
use std::path::Path;

/// Reads a truth video and checks that every value is finite.
pub fn read_truth(path: impl AsRef<Path>) -> Result<Array4<f32>, IoError> {
    let path = path.as_ref();
    let v = super::read::read_stack(path)?;
    check_finite(path, &v)?;
    Ok(v)
}

/// Refuses a video holding NaN or infinite values, naming the first one.
pub fn check_finite(path: &Path, v: &Array4<f32>) -> Result<(), IoError> {
    let count = v.iter().filter(|x| !x.is_finite()).count();
    if count == 0 {
        return Ok(());
    }
    let ((f, r, c, ch), x) = v.indexed_iter().find(|(_, x)| !x.is_finite()).expect("a non-finite value was counted");
    Err(IoError::unexpected(path, "finite values", format!("{count} NaN or infinite values (the first, {x}, at frame {f}, row {r}, col {c}, channel {ch})")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_truth_with_nan_is_refused_with_the_first_position() {
        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("truth.npy");
        let mut v = Array4::<f32>::ones((3, 4, 5, 1));
        v[[1, 2, 3, 0]] = f32::NAN;
        v[[2, 0, 0, 0]] = f32::INFINITY;
        crate::io::write_npy(&p, v.view()).unwrap();
        let e = read_truth(&p).unwrap_err().to_string();
        assert!(e.contains("truth.npy") && e.contains("2 NaN or infinite") && e.contains("frame 1, row 2, col 3"), "{e}");
        v[[1, 2, 3, 0]] = 0.5;
        v[[2, 0, 0, 0]] = 0.5;
        crate::io::write_npy(&p, v.view()).unwrap();
        assert_eq!(read_truth(&p).unwrap(), v);
    }
}
