//! The session folder's layout (`raw/`, `rec/`, `capture.toml`, `psf.tiff`) and its
//! creation: a new folder is refused unless empty, and gets the capture description
//! and the PSF before anything runs.

use super::preview;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// Raw capture folder inside a session folder.
pub const RAW_DIR: &str = "raw";
/// Reconstructions inside a session folder (`rec/frame_NNNNNN/`).
pub const REC_DIR: &str = "rec";
/// The session's capture description and PSF.
pub const CAPTURE_TOML: &str = "capture.toml";
pub const PSF_TIFF: &str = "psf.tiff";

/// Refuse a session folder that exists and is not empty (`--resume` continues one).
pub fn check_new_folder(dir: &Path) -> Result<()> {
    if dir.exists() {
        if !dir.is_dir() {
            bail!("{}: exists and is not a folder", dir.display());
        }
        let mut entries = std::fs::read_dir(dir).with_context(|| format!("{}: cannot list the folder", dir.display()))?;
        if entries.next().is_some() {
            bail!(
                "{}: the output folder is not empty; choose a new folder, or continue that session with `rollcam run --resume {}`",
                dir.display(),
                dir.display()
            );
        }
    }
    Ok(())
}

/// Where the session's PSF comes from.
pub enum PsfInput<'a> {
    /// A calibration image on disk, copied byte for byte.
    File(&'a Path),
    /// An image in memory (the simulated bench's), written as 16-bit TIFF.
    Image(&'a ndarray::Array3<f32>),
}

/// Create a new session folder (refusing one that is not empty) and write the capture
/// description and the PSF into it. Returns the PSF's path in the folder.
pub fn create_folder(dir: &Path, cfg: &crate::model::capture::CaptureConfig, psf: PsfInput) -> Result<PathBuf> {
    check_new_folder(dir)?;
    for sub in ["", REC_DIR, preview::PREVIEW_DIR] {
        let d = dir.join(sub);
        std::fs::create_dir_all(&d).with_context(|| format!("{}: cannot create the folder", d.display()))?;
    }
    match psf {
        PsfInput::File(p) => {
            let bytes = crate::io::input::read_bounded(p, crate::io::ByteBudget::system().limit_bytes)
                .with_context(|| format!("{}: cannot read the PSF", p.display()))?;
            rollcam_hw::record::write_atomic(dir, PSF_TIFF, &bytes)?;
        }
        PsfInput::Image(img) => crate::io::write_tiff_u16(dir.join(PSF_TIFF), img.view())?,
    }
    rollcam_hw::record::write_atomic(dir, CAPTURE_TOML, cfg.to_toml().as_bytes())?;
    Ok(dir.join(PSF_TIFF))
}
