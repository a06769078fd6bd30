//! Simulated captures on disk, as a bench would give them, with their ground truth:
//! the folders `rollcam simulate` (and `rollcam demo`) write. One capture is
//! `raw.tiff`; consecutive captures are a capture folder in the recorder's format
//! (`capture.json`, `frame_NNNNNN.tiff` + `.json` with device timestamps), so they
//! replay and reconstruct like recorded ones. Both get the PSF as a camera would record
//! it (`psf.tiff`), `capture.toml` and the truth (`truth.npy`, `truth.tiff`).
//!
//! Key frames of a second, global-shutter camera ([`write_keyframes`]) lie beside the
//! raw: `keyframe_NNN.tiff` (16-bit) and `keyframe_psf.tiff` (the lens blur, float32).
//!
//! A capture on a simulated bench ([`write_bench_capture`]) adds what the bench knows
//! and a real one would not: `sensor_truth.json` and `sensor_fpn.tiff` (the defects and
//! fixed-pattern dark the sensor really has, to score detectors against), and the
//! calibration shots taken with the same sensor under `calibration-shots/`
//! (`dark/dark_NNN.tiff`, `psf/psf_NNN.tiff`, `background/background_NNN.tiff`, 16-bit).
//! capture.toml declares none of it (no saturation level, no defects): the sensor model
//! is provenance in its `[simulation]` table.

use crate::lab::hardware;
use crate::model::capture::CaptureConfig;
use crate::sim::keyframe::{keyframe_file, KEYFRAME_PSF_FILE};
use crate::sim::{psf_counts, CalibrationShots, KeyFrames, SequenceSimulation, SimSetup, SimulatedSensor, Simulation};
use anyhow::{Context, Result};
use ndarray::{Array2, Array3, Axis};
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

/// Folder of the calibration shots inside a simulated capture folder.
pub const CALIBRATION_SHOTS_DIR: &str = "calibration-shots";
/// The files `simulate` may write at the top of its folder (for the output-folder
/// check; a sequence's frames add `frame_NNNNNN.tiff`/`.json`).
pub const SIMULATION_FILES: &[&str] = &["raw.tiff", "psf.tiff", "truth.npy", "truth.tiff", "capture.toml", "capture.json", SENSOR_TRUTH_FILE, SENSOR_FPN_FILE];
/// The sensor's real defects (hot and stuck pixel positions and levels).
pub const SENSOR_TRUTH_FILE: &str = "sensor_truth.json";
/// The sensor's real fixed-pattern dark offsets, float32 ADU around the dark level.
pub const SENSOR_FPN_FILE: &str = "sensor_fpn.tiff";

/// One simulated capture of `setup` on `bench` into `out` (created): what
/// [`write_capture`] writes, plus `sensor_truth.json` and `sensor_fpn.tiff` when the
/// sensor has defects, and the calibration `shots` under `calibration-shots/` (recorded
/// in capture.toml's `[simulation.calibration_shots]`). capture.toml comes last.
pub fn write_bench_capture(
    out: &Path,
    setup: &SimSetup,
    bench: &SimulatedSensor,
    cfg: &CaptureConfig,
    simulation: &Simulation,
    shots: Option<&CalibrationShots>,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create the folder", out.display()))?;
    crate::io::write_tiff_u16(out.join("raw.tiff"), simulation.raw.view().insert_axis(Axis(2)))?;
    if let Some(map) = &bench.defects {
        crate::io::write_tiff_f32(out.join(SENSOR_FPN_FILE), map.dark_fpn_adu.view().insert_axis(Axis(2)))?;
        let mut truth = map.truth();
        truth.dark_fpn_file = Some(SENSOR_FPN_FILE.into());
        let text = serde_json::to_string_pretty(&truth).context("sensor truth as JSON")?;
        crate::io::write_text_atomic(&out.join(SENSOR_TRUTH_FILE), &text)?;
    }
    let mut cfg = cfg.clone();
    if let Some(shots) = shots {
        let dir = out.join(CALIBRATION_SHOTS_DIR);
        write_frames(&dir.join("dark"), "dark", &shots.dark)?;
        write_frames(&dir.join("psf"), "psf", &shots.psf)?;
        if !shots.background.is_empty() {
            write_frames(&dir.join("background"), "background", &shots.background)?;
        }
        let mut t = shots.describe();
        t.insert("folder".into(), CALIBRATION_SHOTS_DIR.into());
        cfg.simulation.get_or_insert_with(toml::Table::new).insert("calibration_shots".into(), t.into());
    }
    if bench.defects.is_some() {
        if let Some(toml::Value::Table(t)) = cfg.simulation.as_mut().and_then(|s| s.get_mut("sensor")) {
            t.insert("truth_file".into(), SENSOR_TRUTH_FILE.into());
            t.insert("dark_fpn_file".into(), SENSOR_FPN_FILE.into());
        }
    }
    write_psf_and_truth(out, setup, &simulation.truth, &cfg)
}

/// Key frames of a second camera into `out` (created): `keyframe_NNN.tiff` (16-bit)
/// and, with a lens blur, `keyframe_psf.tiff` (float32, unit sum). Their
/// `[[keyframes]]` tables go into the capture description the caller writes next.
pub fn write_keyframes(out: &Path, keys: &KeyFrames) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create the folder", out.display()))?;
    for (r, img) in keys.refs.iter().zip(&keys.images) {
        crate::io::write_tiff_u16(out.join(&r.file), img.view().insert_axis(Axis(2)))?;
    }
    if let Some(psf) = &keys.psf {
        crate::io::write_tiff_f32(out.join(KEYFRAME_PSF_FILE), psf.view().insert_axis(Axis(2)))?;
    }
    Ok(())
}

/// The files [`write_keyframes`] writes for `count` key frames (with the lens blur's
/// when `blur`), for the output-folder check.
pub fn keyframe_files(count: usize, blur: bool) -> Vec<String> {
    let mut names: Vec<String> = (0..count).map(keyframe_file).collect();
    if blur {
        names.push(KEYFRAME_PSF_FILE.to_string());
    }
    names
}

/// `frames` as `dir/{stem}_NNN.tiff` (16-bit, `dir` created).
fn write_frames(dir: &Path, stem: &str, frames: &[Array2<f32>]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create the folder", dir.display()))?;
    for (k, f) in frames.iter().enumerate() {
        crate::io::write_tiff_u16(dir.join(format!("{stem}_{k:03}.tiff")), f.view().insert_axis(Axis(2)))?;
    }
    Ok(())
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
