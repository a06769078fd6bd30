//! Reading a capture folder as a sequence: the complete raw frames in sequence
//! order, their start times (device timestamps, or sequence numbers times a given
//! frame period), checked and prepared like a single capture (dark level,
//! downsampling, PSF normalisation).

use crate::model::capture::CaptureConfig;
use crate::model::prepare::{prepare, DataMask, Plane, SensorInput, SensorReport};
use crate::model::time_grid::TimeSource;
use crate::solve::sequence::error::{check_spacing, SequenceError};
use ndarray::{Array3, ArrayView3};
use rollcam_files::capture::{CaptureReader, RecordError};
use rollcam_files::frame::FrameStatus;
use serde::Serialize;
use std::path::Path;

impl From<RecordError> for SequenceError {
    fn from(e: RecordError) -> Self {
        SequenceError::Capture(e.to_string())
    }
}

/// A frame left out, and why.
#[derive(Clone, Debug, Serialize)]
pub struct Skipped {
    pub file: String,
    pub reason: String,
}

/// The raw frames of a capture folder, prepared.
pub struct SequenceInput {
    /// The TIFF of every capture used, in order.
    pub files: Vec<String>,
    /// Their sequence numbers.
    pub sequence: Vec<u64>,
    /// First-row exposure start of each relative to the first, microseconds.
    pub start_us: Vec<f64>,
    pub source: TimeSource,
    /// Mean spacing of the device timestamps, microseconds (when they exist).
    pub timestamp_period_us: Option<f64>,
    pub raws: Vec<Plane>,
    /// Each capture's data-term mask (clipped and defective pixels left out), if any.
    pub masks: Vec<DataMask>,
    /// What sensor handling did to each capture.
    pub sensor: Vec<SensorReport>,
    pub psf: Plane,
    pub raw_dark: Vec<f64>,
    pub psf_dark: f64,
    pub dark_estimated: bool,
    pub skipped: Vec<Skipped>,
}

/// Read `dir` (a folder the recorder wrote) under `cfg`, with the PSF image `psf` and
/// what `sensor` knows of the sensor (calibration, background).
/// Start times come from the device timestamps, or from `frame_period_us` times the
/// sequence numbers when it is given. Consecutive captures must start at least one
/// video frame time and one exposure apart.
pub fn load_capture_folder(
    dir: &Path,
    psf: ArrayView3<f32>,
    psf_name: &str,
    cfg: &CaptureConfig,
    sensor: &SensorInput,
    frame_period_us: Option<f64>,
) -> Result<SequenceInput, SequenceError> {
    let reader = CaptureReader::open(dir)?;
    let name = |seq: u64, ext: &str| dir.join(format!("frame_{seq:06}.{ext}")).display().to_string();
    let mut skipped = Vec::new();
    let mut used = Vec::new();
    for (i, meta) in reader.metas().iter().enumerate() {
        match meta.status {
            FrameStatus::Complete => used.push(i),
            FrameStatus::Dropped => skipped.push(Skipped { file: name(meta.sequence, "json"), reason: "dropped by the camera: no pixels".into() }),
            FrameStatus::Incomplete => skipped.push(Skipped {
                file: name(meta.sequence, "tiff"),
                reason: format!("incomplete: {} of {} pixels", meta.valid_pixels, meta.width as u64 * meta.height as u64),
            }),
        }
    }
    for p in reader.orphans() {
        skipped
            .push(Skipped { file: p.display().to_string(), reason: "no sidecar (.json): the recorder writes it last, so the frame was not finished".into() });
    }
    for s in &skipped {
        tracing::warn!(file = %s.file, reason = %s.reason, "frame left out of the sequence");
    }
    if used.is_empty() {
        return Err(SequenceError::NoFrames { dir: dir.display().to_string(), found: reader.len(), skipped: skipped.len() });
    }
    let metas: Vec<_> = used.iter().map(|&i| reader.metas()[i].clone()).collect();

    // Sizes: every frame as the first and as capture.toml says.
    let first = &metas[0];
    for m in &metas {
        if (m.width as usize, m.height as usize) != (cfg.cols, cfg.rows) {
            let expected = if std::ptr::eq(m, first) {
                format!("{} x {} (cols x rows of the capture description)", cfg.cols, cfg.rows)
            } else {
                format!("{} x {} as {} and the capture description", cfg.cols, cfg.rows, name(first.sequence, "tiff"))
            };
            return Err(SequenceError::Size { file: name(m.sequence, "tiff"), got_rows: m.height, got_cols: m.width, expected });
        }
    }

    // Start times.
    let timing = cfg.timing();
    let tf = timing.frame_time_us();
    let te = timing.exposure_us;
    let stamps: Vec<u64> = metas.iter().map(|m| m.device_timestamp_ns).collect();
    let have_stamps = metas.len() > 1 && stamps[1..].iter().all(|&t| t != 0) && stamps.windows(2).all(|w| w[1] > w[0]);
    let timestamp_period_us =
        have_stamps.then(|| (stamps[stamps.len() - 1] - stamps[0]) as f64 / 1e3 / (metas[metas.len() - 1].sequence - metas[0].sequence).max(1) as f64);
    let (start_us, source) = match frame_period_us {
        Some(p) => {
            if !(p.is_finite() && p > 0.0) {
                return Err(SequenceError::Period(p));
            }
            check_spacing("frame period (--frame-period-us)".into(), p, tf, te)?;
            if let Some(ts) = timestamp_period_us {
                if ((ts - p) / p).abs() > 0.01 {
                    tracing::warn!(given_us = p, timestamps_us = ts, "the given frame period differs from the device timestamps' by more than 1%");
                }
            }
            let s0 = metas[0].sequence;
            (metas.iter().map(|m| (m.sequence - s0) as f64 * p).collect::<Vec<f64>>(), TimeSource::FramePeriod { period_us: p })
        }
        None => {
            let hint = reader
                .session()
                .applied
                .as_ref()
                .and_then(|a| a.frame_rate_hz)
                .map(|hz| format!(" (the camera's applied frame rate, {hz} Hz, gives {:.1} us)", 1e6 / hz))
                .unwrap_or_default();
            for (c, m) in metas.iter().enumerate().skip(1) {
                if m.device_timestamp_ns == 0 {
                    return Err(SequenceError::NoTimestamps { file: name(m.sequence, "json"), hint });
                }
                let prev = &metas[c - 1];
                if m.device_timestamp_ns <= prev.device_timestamp_ns {
                    return Err(SequenceError::TimestampOrder {
                        file: name(m.sequence, "json"),
                        got: m.device_timestamp_ns,
                        prev_file: name(prev.sequence, "json"),
                        prev: prev.device_timestamp_ns,
                    });
                }
                let gap_us = (m.device_timestamp_ns - prev.device_timestamp_ns) as f64 / 1e3;
                check_spacing(format!("{}: device_timestamp_ns - {}'s", name(m.sequence, "json"), name(prev.sequence, "json")), gap_us, tf, te)?;
            }
            (stamps.iter().map(|&t| (t - stamps[0]) as f64 / 1e3).collect(), TimeSource::DeviceTimestamps)
        }
    };

    // Pixels, prepared like one capture each.
    let mut files = Vec::new();
    let mut raws = Vec::new();
    let mut masks = Vec::new();
    let mut reports = Vec::new();
    let mut raw_dark = Vec::new();
    let mut psf_plane = None;
    let (mut psf_dark, mut dark_estimated) = (0.0, false);
    for &i in &used {
        let frame = reader.read_frame(i)?;
        let file = name(frame.meta.sequence, "tiff");
        let img = Array3::from_shape_vec((frame.meta.height as usize, frame.meta.width as usize, 1), frame.pixels.iter().map(|&v| v as f32).collect())
            .map_err(|_| SequenceError::Size {
                file: file.clone(),
                got_rows: frame.meta.height,
                got_cols: frame.meta.width,
                expected: format!("{} samples", frame.pixels.len()),
            })?;
        let mut p = prepare(img.view(), &file, psf, psf_name, cfg, sensor)?;
        for w in &p.sensor.warnings {
            tracing::warn!("{w}");
        }
        masks.push(std::mem::take(&mut p.data_mask));
        reports.push(std::mem::take(&mut p.sensor));
        raw_dark.push(p.raw_dark);
        psf_dark = p.psf_dark;
        dark_estimated = p.dark_estimated;
        raws.push(p.raw.remove(0));
        if psf_plane.is_none() {
            psf_plane = Some(p.psf.remove(0));
        }
        files.push(file);
    }
    Ok(SequenceInput {
        files,
        sequence: metas.iter().map(|m| m.sequence).collect(),
        start_us,
        source,
        timestamp_period_us,
        raws,
        masks,
        sensor: reports,
        psf: psf_plane.expect("at least one frame"),
        raw_dark,
        psf_dark,
        dark_estimated,
        skipped,
    })
}
