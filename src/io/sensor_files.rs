//! The sensor inputs of a capture on disk: the bench calibration folder (from
//! `--calibration`, else the capture description's `[calibration] dir`), a background
//! frame as shot (`--background`, else the calibration's), and the raw file's full
//! scale. What they mean is `crate::model::prepare::SensorInput`'s.

use std::path::{Path, PathBuf};

use ndarray::Array3;

use super::calibration::{load_calibration, PSF_FILE};
use super::error::IoError;
use super::read_image;
use crate::model::capture::CalibrationRef;
use crate::model::keyframe::KeyFrameRef;
use crate::model::prepare::KeyFrameImage;
use crate::model::prepare::SensorInput;
use crate::model::sensor::Calibration;

/// The calibration and background of one capture, loaded.
#[derive(Clone, Debug, Default)]
pub struct SensorFiles {
    pub calibration_dir: Option<PathBuf>,
    pub calibration: Option<Calibration>,
    pub background_path: Option<PathBuf>,
    pub background: Option<Array3<f32>>,
    /// The capture description's key frames, read (files relative to its folder).
    pub keyframes: Vec<KeyFrameImage>,
}

impl SensorFiles {
    /// Load what is named: `calibration` (a flag) wins over `cfg_calibration` (a capture
    /// description's `[calibration]`, relative to the folder of `config_path`, the file
    /// it came from); `background` is a raw frame of the background as shot.
    pub fn load(
        calibration: Option<&Path>,
        background: Option<&Path>,
        config_path: Option<&Path>,
        cfg_calibration: Option<&CalibrationRef>,
    ) -> Result<SensorFiles, IoError> {
        let from_cfg = cfg_calibration.map(|c| {
            let dir = Path::new(&c.dir);
            match config_path.and_then(Path::parent) {
                Some(base) if dir.is_relative() => base.join(dir),
                _ => dir.to_path_buf(),
            }
        });
        let calibration_dir = calibration.map(Path::to_path_buf).or(from_cfg);
        let calibration = calibration_dir.as_deref().map(load_calibration).transpose()?;
        let background_path = background.map(Path::to_path_buf);
        let background = background.map(read_image).transpose()?;
        if let (Some(path), Some(b)) = (background_path.as_deref(), &background) {
            check_background(path, b)?;
        }
        Ok(SensorFiles { calibration_dir, calibration, background_path, background, keyframes: Vec::new() })
    }

    /// Read the key frames `refs` names (`[[keyframes]]`), files relative to the folder
    /// of `config_path`, the description they came from.
    pub fn with_keyframes(mut self, refs: &[KeyFrameRef], config_path: Option<&Path>) -> Result<SensorFiles, IoError> {
        let at = |f: &str| {
            let p = Path::new(f);
            match config_path.and_then(Path::parent) {
                Some(base) if p.is_relative() => base.join(p),
                _ => p.to_path_buf(),
            }
        };
        self.keyframes = refs
            .iter()
            .map(|r| {
                let path = at(&r.file);
                let image = read_image(&path)?;
                let psf = r.psf.as_deref().map(|p| read_image(at(p))).transpose()?;
                Ok(KeyFrameImage { name: path.display().to_string(), spec: r.clone(), image, full_scale: crate::io::sample_full_scale(&path), psf })
            })
            .collect::<Result<_, IoError>>()?;
        Ok(self)
    }

    /// The sensor input of `prepare` for a raw of full scale `raw_full_scale`; `psf_clean`
    /// when the PSF is the calibration's (already dark-subtracted).
    pub fn input(&self, raw_full_scale: Option<f64>, psf_clean: bool) -> SensorInput<'_> {
        SensorInput {
            calibration: self.calibration.as_ref(),
            background: self.background.as_ref().map(|b| b.view()),
            file_full_scale: raw_full_scale,
            psf_clean,
            keyframes: &self.keyframes,
            ..SensorInput::default()
        }
    }

    /// The calibration's PSF and a name for it, when it has one.
    pub fn psf(&self) -> Option<(String, &Array3<f32>)> {
        let psf = self.calibration.as_ref()?.psf.as_ref()?;
        let dir = self.calibration_dir.as_deref().unwrap_or(Path::new("."));
        Some((dir.join(PSF_FILE).display().to_string(), psf))
    }

    /// The calibration's `psf.tiff`, when the folder has one.
    pub fn psf_path(&self) -> Option<PathBuf> {
        self.calibration.as_ref()?.psf.as_ref()?;
        Some(self.calibration_dir.as_ref()?.join(PSF_FILE))
    }

    /// The folder's path for a summary.
    pub fn calibration_name(&self) -> Option<String> {
        self.calibration_dir.as_ref().map(|p| p.display().to_string())
    }

    /// The background's path for a summary (the flag's file, or the calibration's).
    pub fn background_name(&self) -> Option<String> {
        match (&self.background_path, &self.calibration) {
            (Some(p), _) => Some(p.display().to_string()),
            (None, Some(c)) if c.background.is_some() => {
                self.calibration_dir.as_ref().map(|d| d.join(super::calibration::BACKGROUND_FILE).display().to_string())
            }
            _ => None,
        }
    }
}
/// A background frame is counts as shot: finite and non-negative (a negative float
/// frame, subtracted, would add light that was never there).
fn check_background(path: &Path, b: &Array3<f32>) -> Result<(), IoError> {
    let (_, n, c) = b.dim();
    match b.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v >= 0.0)) {
        None => Ok(()),
        Some((i, v)) => Err(IoError::unexpected(
            path,
            "a background frame of non-negative counts as shot (--background)",
            format!("{v} at row {}, col {}", i / (n * c), i / c % n),
        )),
    }
}
