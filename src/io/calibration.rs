//! A bench calibration folder on disk: `calibration.toml` (what was shot and measured,
//! [`CalibrationRecord`]) beside `dark.tiff`, `defects.tiff`, `psf.tiff` and
//! `background.tiff`, each present when its record is. Arrays are float32 TIFFs
//! (row, col, channel); the defect map is a 16-bit TIFF of [`crate::model::sensor::Defect`]
//! codes.

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, Axis};

use super::error::IoError;
use super::{read_image, write_text_atomic, write_tiff_f32, write_tiff_u16};
use crate::model::sensor::{Calibration, CalibrationRecord};

pub const RECORD_FILE: &str = "calibration.toml";
pub const DARK_FILE: &str = "dark.tiff";
pub const DEFECTS_FILE: &str = "defects.tiff";
pub const PSF_FILE: &str = "psf.tiff";
pub const BACKGROUND_FILE: &str = "background.tiff";

/// Write `cal` into `dir` (which must exist): the arrays first, `calibration.toml`
/// last, so its presence means the folder is complete.
pub fn write_calibration(dir: &Path, cal: &Calibration) -> Result<(), IoError> {
    if let Some(d) = &cal.dark {
        write_tiff_f32(dir.join(DARK_FILE), d.view())?;
    }
    if let Some(m) = &cal.defects {
        write_tiff_u16(dir.join(DEFECTS_FILE), m.mapv(f32::from).insert_axis(Axis(2)).view())?;
    }
    if let Some(p) = &cal.psf {
        write_tiff_f32(dir.join(PSF_FILE), p.view())?;
    }
    if let Some(b) = &cal.background {
        write_tiff_f32(dir.join(BACKGROUND_FILE), b.view())?;
    }
    let text = toml::to_string_pretty(&cal.record).map_err(|e| IoError::bad_input(&dir.join(RECORD_FILE), e.to_string()))?;
    write_text_atomic(&dir.join(RECORD_FILE), &text)
}

/// Read a calibration folder: `calibration.toml` and every array it records, each
/// checked against the record's size and channels (errors name the file).
pub fn load_calibration(dir: &Path) -> Result<Calibration, IoError> {
    let record_path = dir.join(RECORD_FILE);
    if !dir.is_dir() {
        return Err(IoError::unexpected(dir, "a calibration folder (made by `rollcam calibrate`)", "no such folder"));
    }
    let text = crate::io::input::read_text(&record_path).map_err(|e| IoError::os(&record_path, "cannot read the calibration record", e))?;
    let record: CalibrationRecord = toml::from_str(&text).map_err(|e| IoError::malformed(&record_path, "TOML", e.message()))?;
    if record.rows == 0 || record.cols == 0 || !(record.channels == 1 || record.channels == 3) {
        return Err(IoError::unexpected(
            &record_path,
            "rows and cols of at least 1 and channels 1 or 3",
            format!("rows = {}, cols = {}, channels = {}", record.rows, record.cols, record.channels),
        ));
    }
    if let Some(s) = record.saturation_level {
        if !(s.is_finite() && s > 0.0) {
            return Err(IoError::unexpected(&record_path, "saturation_level: a positive count", s.to_string()));
        }
    }
    let image = |name: &str, channels: Option<usize>| -> Result<Array3<f32>, IoError> {
        let path: PathBuf = dir.join(name);
        let img = read_image(&path)?;
        let (r, c, ch) = img.dim();
        if (r, c) != (record.rows, record.cols) || channels.is_some_and(|want| want != ch) {
            let want = channels.map(|w| format!(" x {w} channels")).unwrap_or_default();
            return Err(IoError::unexpected(
                &path,
                format!("{} x {}{want}, as {RECORD_FILE} records", record.rows, record.cols),
                format!("{r} x {c} x {ch} channels"),
            ));
        }
        if let Some((i, _)) = img.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(IoError::unexpected(&path, "finite values", format!("a NaN or infinite value at sample {i}")));
        }
        Ok(img)
    };
    let dark = record.dark.as_ref().map(|_| image(DARK_FILE, Some(record.channels))).transpose()?;
    let defects = match record.defects {
        None => None,
        Some(_) => {
            let m = image(DEFECTS_FILE, Some(1))?;
            if let Some(v) = m.iter().find(|&&v| !(0.0..=4.0).contains(&v) || v.fract() != 0.0) {
                return Err(IoError::unexpected(&dir.join(DEFECTS_FILE), "defect codes 0 (good) to 4", format!("the value {v}")));
            }
            Some(m.index_axis(Axis(2), 0).mapv(|v| v as u8))
        }
    };
    let psf = record.psf.as_ref().map(|_| image(PSF_FILE, Some(record.channels))).transpose()?;
    let background = record.background.as_ref().map(|_| image(BACKGROUND_FILE, Some(record.channels))).transpose()?;
    Ok(Calibration { record, dark, defects: defects.map(|d: Array2<u8>| d), psf, background })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::sensor::{DarkRecord, DefectRecord};

    #[test]
    fn a_folder_round_trips_and_a_wrong_size_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let (m, n) = (6, 5);
        let dark = Array3::from_shape_fn((m, n, 1), |(i, j, _)| 100.0 + (i * n + j) as f32 * 0.25);
        let mut defects = Array2::<u8>::zeros((m, n));
        defects[[2, 3]] = 1;
        defects[[4, 0]] = 2;
        let record = CalibrationRecord {
            rows: m,
            cols: n,
            channels: 1,
            saturation_level: Some(4095.0),
            created_utc: "2026-11-23T00:00:00Z".into(),
            dark: Some(DarkRecord { frames: 8, files: vec![], median_level: 100.0, fixed_pattern_rms: 1.0, read_noise: 2.0 }),
            defects: Some(DefectRecord { hot: 1, stuck: 1, noisy: 0, dead: 0, total: 2, fraction: 2.0 / 30.0 }),
            psf: None,
            background: None,
        };
        let cal = Calibration { record: record.clone(), dark: Some(dark.clone()), defects: Some(defects.clone()), psf: None, background: None };
        write_calibration(dir.path(), &cal).unwrap();
        let back = load_calibration(dir.path()).unwrap();
        assert_eq!(back.record, record);
        assert_eq!(back.dark.unwrap(), dark);
        assert_eq!(back.defects.unwrap(), defects);
        assert!(back.psf.is_none() && back.background.is_none());

        // A dark of the wrong size is named with what was expected.
        write_tiff_f32(dir.path().join(DARK_FILE), Array3::<f32>::zeros((5, 5, 1)).view()).unwrap();
        let e = load_calibration(dir.path()).unwrap_err().to_string();
        assert!(e.contains(DARK_FILE) && e.contains("6 x 5"), "{e}");

        // A record naming a file that is not there.
        std::fs::remove_file(dir.path().join(DARK_FILE)).unwrap();
        let e = load_calibration(dir.path()).unwrap_err().to_string();
        assert!(e.contains(DARK_FILE), "{e}");

        let e = load_calibration(&dir.path().join("nowhere")).unwrap_err().to_string();
        assert!(e.contains("nowhere") && e.contains("calibration folder"), "{e}");
    }
}
