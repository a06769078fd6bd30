//! Simulated captures on disk, as a bench would give them, with their ground truth:
//! the folders `rollcam simulate` (and `rollcam demo`) write. One capture is
//! `raw.tiff`; consecutive captures are a capture folder in the recorder's format
//! (`capture.json`, `frame_NNNNNN.tiff` + `.json` with device timestamps), so they
//! replay and reconstruct like recorded ones. Both get the PSF as a camera would record
//! it (`psf.tiff`), `capture.toml` and the truth (`truth.npy`, `truth.tiff`).

use crate::lab::hardware;
use crate::model::capture::CaptureConfig;
use crate::sim::{psf_counts, SequenceSimulation, SimSetup, Simulation};
use anyhow::{Context, Result};
use ndarray::{Array3, Axis};
use rollcam_hw::camera::{host_now_ns, CameraInfo, Frame, FrameMeta, FrameStatus};
use rollcam_hw::record::{CaptureSession, Recorder};
use std::path::Path;

/// One simulated capture of `setup` into `out` (created): `raw.tiff`, `psf.tiff`,
/// `truth.npy`, `truth.tiff` and `capture.toml` (`cfg`, the simulation's annotated
/// capture description).
pub fn write_capture(out: &Path, setup: &SimSetup, cfg: &CaptureConfig, simulation: &Simulation) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create the folder", out.display()))?;
    crate::io::write_tiff_u16(out.join("raw.tiff"), simulation.raw.view().insert_axis(Axis(2)))?;
    write_psf_and_truth(out, setup, &simulation.truth, cfg)
}

/// Consecutive simulated captures of `setup`, `period_us` apart, as a capture folder
/// in `out` (the recorder's format; the camera is `sim:simulate`), with `psf.tiff`,
/// `capture.toml` and the truth on the global video grid.
pub fn write_sequence(out: &Path, setup: &SimSetup, period_us: f64, s: &SequenceSimulation) -> Result<()> {
    let camera = CameraInfo {
        backend: "sim".into(),
        id: "simulate".into(),
        vendor: None,
        model: Some("rollcam simulator".into()),
        serial: None,
        address: None,
        protocol: None,
    };
    let settings = hardware::applied_settings(&setup.cfg, Some(1e6 / period_us));
    let mut session = CaptureSession::new(camera.clone());
    session.applied = Some(settings.clone());
    session.frames_requested = Some(s.raws.len() as u64);
    let mut rec = Recorder::create(out, session)?;
    for (c, raw) in s.raws.iter().enumerate() {
        let pixels: Vec<u16> = raw.iter().map(|&v| v.clamp(0.0, 65535.0) as u16).collect();
        let meta = FrameMeta {
            camera: camera.spec(),
            frame_id: c as u64,
            sequence: c as u64,
            device_timestamp_ns: (s.start_us[c] * 1e3).round() as u64,
            host_timestamp_ns: host_now_ns(),
            status: FrameStatus::Complete,
            width: settings.roi.width,
            height: settings.roi.height,
            bit_depth: 16,
            valid_pixels: pixels.len() as u64,
            settings: settings.clone(),
        };
        rec.write_frame(&Frame { meta, pixels })?;
    }
    rec.finish(None)?;
    write_psf_and_truth(out, setup, &s.truth, &s.config)
}

/// `psf.tiff` (the PSF on the raw images' dark level), `truth.npy`, `truth.tiff`,
/// `capture.toml`.
fn write_psf_and_truth(out: &Path, setup: &SimSetup, truth: &Array3<f32>, cfg: &CaptureConfig) -> Result<()> {
    crate::io::write_tiff_u16(out.join("psf.tiff"), psf_counts(setup.psf.view(), setup.noise.dark_level_adu).view())?;
    let truth = truth.view().insert_axis(Axis(3));
    crate::io::write_npy(out.join("truth.npy"), truth)?;
    crate::io::write_tiff_stack_f32(out.join("truth.tiff"), truth)?;
    crate::io::write_text_atomic(&out.join("capture.toml"), &cfg.to_toml())?;
    Ok(())
}
