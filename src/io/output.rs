//! The folder a reconstruction writes: the video (float32 TIFF stack and `.npy`), a
//! contact sheet, an animated GIF, the trace (`trace.csv`, `trace.png`) and
//! `summary.json`. Every file is written atomically; `summary.json` comes last, so its
//! presence means the folder is complete.

use crate::io::{self, Display, IoError, PlotSpec, Series};
use crate::model::capture::CaptureConfig;
use crate::model::prepare::{Prepared, SensorReport};
use crate::solve::reconstruct::{Reconstruction, SolveParams};
use crate::solve::trace;
use ndarray::ArrayView4;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Where the inputs came from (for the summary).
#[derive(Clone, Debug, Default, Serialize)]
pub struct Inputs {
    pub raw: Option<String>,
    pub psf: Option<String>,
    pub config: Option<String>,
    pub truth: Option<String>,
    /// The bench calibration folder, when one was used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<String>,
    /// The background frame subtracted, when one was.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub background: Option<String>,
}

/// Everything `summary.json` records.
#[derive(Serialize)]
pub struct Summary<'a> {
    pub rollcam_version: &'static str,
    pub inputs: &'a Inputs,
    pub capture: &'a CaptureConfig,
    pub params: &'a SolveParams,
    /// (frames, rows, cols, channels) of the video.
    pub video_shape: [usize; 4],
    /// A still (global shutter): one frame, no time; the frame time is the exposure.
    pub still: bool,
    pub frame_time_us: f64,
    pub frames_per_second: f64,
    pub sensor_offset: (usize, usize),
    pub raw_dark_level: f64,
    pub psf_dark_level: f64,
    pub dark_level_estimated: bool,
    /// The sensor: where the dark came from, clipped and defective pixels, the data
    /// term's mask, warnings.
    pub sensor: &'a SensorReport,
    pub channels: &'a [crate::solve::reconstruct::ChannelReport],
    /// What a scene declaration left out and what that saved (absent: nothing declared).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scene: Option<&'a crate::solve::reconstruct::SceneReport>,
    /// What the static + dynamic model changed (absent: the plain video was solved).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub static_background: Option<&'a crate::solve::channel::StaticDynamicReport>,
    /// The frames `contact.png` shows (all up to 48, else 48 evenly spaced); empty
    /// when no contact sheet is written.
    pub contact_sheet_frames: Vec<usize>,
    /// How strongly the data constrain each frame (see `FrameSensitivity`).
    pub frame_sensitivity: &'a crate::solve::reconstruct::FrameSensitivity,
    /// How the solve was planned: its mode and why, the weight, where it ran (absent:
    /// not planned; see `crate::solve::plan`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plan: Option<&'a crate::solve::plan::PlanReport>,
    /// How the frames were split across MPI ranks (absent: one process).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mpi: Option<&'a crate::solve::channel::SplitReport>,
    /// How `tau_rel` was chosen by held-out pixels (absent: as given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tau_search: Option<&'a crate::solve::tau_search::TauSearchReport>,
    /// How well the video explains the data against the noise (absent: not measured;
    /// see `crate::solve::fit`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit: Option<&'a crate::solve::fit::FitReport>,
    /// Wall seconds of the whole solve (all channels, in parallel).
    pub seconds: f64,
    /// The solve's seconds as estimated before it started (the usual iterations under
    /// the stop rule; `null`: not estimated).
    pub estimated_seconds: Option<f64>,
    /// Whether every channel's solve ended by the stop rule's convergence test (false:
    /// an iteration cap, a time budget or a stop request ended one first).
    pub converged: bool,
    /// Worst channel's relative error after the best scale, PSNR and relative error
    /// against the truth, when given (each channel's baselines are in `channels`).
    pub rel_error_scaled: Option<f64>,
    pub psnr_db: Option<f64>,
    pub rel_error: Option<f64>,
    /// Worst channel's motion error against the truth
    /// ([`crate::solve::trace::motion_error`]: a still scores 1, the truth 0), when a
    /// truth that moves was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion_error: Option<f64>,
    /// Why a channel has no error figures although a truth was given (absent: every
    /// channel has them, or no truth).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_undefined: Option<&'static str>,
    pub files: Vec<String>,
}

impl<'a> Summary<'a> {
    /// What `summary.json` records of a reconstruction (`files`: the folder's file
    /// names, empty when nothing is written). The worst channel's error is reported.
    pub fn new(
        rec: &'a Reconstruction,
        cfg: &'a CaptureConfig,
        params: &'a SolveParams,
        inputs: &'a Inputs,
        prepared: &'a Prepared,
        seconds: f64,
        files: Vec<String>,
    ) -> Self {
        let worst = |f: fn(&trace::Error) -> f64, better_low: bool| -> Option<f64> {
            let vals: Vec<f64> = rec.channels.iter().filter_map(|c| c.stats.error.as_ref().map(f)).collect();
            if vals.is_empty() {
                None
            } else if better_low {
                Some(vals.iter().cloned().fold(f64::MIN, f64::max))
            } else {
                Some(vals.iter().cloned().fold(f64::MAX, f64::min))
            }
        };
        let (k, m, n, c) = rec.video.dim();
        Summary {
            rollcam_version: env!("CARGO_PKG_VERSION"),
            inputs,
            capture: cfg,
            params,
            video_shape: [k, m, n, c],
            still: cfg.timing().is_still(),
            frame_time_us: rec.frame_time_us,
            frames_per_second: 1e6 / rec.frame_time_us,
            sensor_offset: rec.sensor_offset,
            raw_dark_level: prepared.raw_dark,
            psf_dark_level: prepared.psf_dark,
            dark_level_estimated: prepared.dark_estimated,
            sensor: &prepared.sensor,
            channels: &rec.channels,
            scene: rec.scene.as_ref(),
            static_background: rec.static_background.as_ref().map(|s| &s.report),
            contact_sheet_frames: if files.iter().any(|f| f == "contact.png") { io::contact_sheet_frames(k) } else { Vec::new() },
            frame_sensitivity: &rec.frame_sensitivity,
            plan: rec.plan.as_ref(),
            mpi: rec.split.as_ref(),
            tau_search: rec.tau_search.as_ref(),
            fit: rec.fit.as_ref(),
            seconds,
            estimated_seconds: rec.estimated_seconds,
            converged: rec.converged(),
            rel_error_scaled: worst(|e| e.rel_error_scaled, true),
            psnr_db: worst(|e| e.psnr_db, false),
            rel_error: worst(|e| e.rel_error, true),
            motion_error: rec.channels.iter().filter_map(|c| c.motion_error).reduce(f64::max),
            error_undefined: (inputs.truth.is_some() && rec.channels.iter().any(|c| c.stats.error.is_none())).then_some(trace::ZERO_TRUTH),
            files,
        }
    }
}

/// Every file a reconstruction folder may get (for [`crate::io::out_dir::claim`]).
pub const RECONSTRUCTION_FILES: &[&str] =
    &["video.tiff", "video.npy", "contact.png", "video.gif", "static.tiff", "static.npy", "dynamic.npy", "trace.csv", "trace.png", "trace.svg", "summary.json"];

/// Which files a reconstruction folder gets. Parsed from and shown as its [`name`](Self::name).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputSet {
    /// Everything: video (TIFF, .npy), contact sheet, GIF, trace (CSV, PNG, SVG), summary.
    #[default]
    Full,
    /// `video.npy`, `trace.csv` and `summary.json`.
    Video,
    /// `video.npy` and `summary.json`.
    Minimal,
}

impl OutputSet {
    pub const ALL: [OutputSet; 3] = [OutputSet::Full, OutputSet::Video, OutputSet::Minimal];

    pub fn name(self) -> &'static str {
        match self {
            OutputSet::Full => "full",
            OutputSet::Video => "video",
            OutputSet::Minimal => "minimal",
        }
    }

    /// The video file this set writes (`video.tiff` for `full`, else `video.npy`).
    pub fn video_file(self) -> &'static str {
        match self {
            OutputSet::Full => "video.tiff",
            _ => "video.npy",
        }
    }
}

impl std::fmt::Display for OutputSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for OutputSet {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        OutputSet::ALL.into_iter().find(|o| o.name() == s).ok_or_else(|| format!("unknown output set '{s}': expected full, video or minimal"))
    }
}

/// The video files of a reconstruction folder: `video.npy` always; `video.tiff` and
/// `contact.png` with [`OutputSet::Full`], which also returns the display scaling
/// they used (for further pictures of the same video).
/// `frame_time_us`: the frames' interval, written into `video.tiff` (none for a still).
pub(crate) fn write_video_files(
    out: &Path,
    v: ArrayView4<f32>,
    frame_time_us: Option<f64>,
    set: OutputSet,
    files: &mut Vec<PathBuf>,
) -> Result<Option<Display>, IoError> {
    let path = |name: &str| out.join(name);
    let full = set == OutputSet::Full;
    if full {
        match frame_time_us {
            Some(tf) => io::write_tiff_video_f32(path("video.tiff"), v, tf)?,
            None => io::write_stack(path("video.tiff"), v)?,
        }
        files.push(path("video.tiff"));
    }
    io::write_stack(path("video.npy"), v)?;
    files.push(path("video.npy"));
    if !full {
        return Ok(None);
    }
    let display = Display::auto(v.iter(), 0.1, 99.9);
    io::write_contact_sheet(path("contact.png"), v, 8, &display, 1)?;
    files.push(path("contact.png"));
    Ok(Some(display))
}

/// One solved capture and what it was made from: what its folder records.
#[derive(Clone, Copy)]
pub struct Solved<'a> {
    pub reconstruction: &'a Reconstruction,
    pub cfg: &'a CaptureConfig,
    pub params: &'a SolveParams,
    /// What it was made from, named in summary.json.
    pub inputs: &'a Inputs,
    pub prepared: &'a Prepared,
    /// Wall seconds of the solve.
    pub seconds: f64,
}

/// Write the folder `out` with the files of `set` for `solved`; returns the files written.
pub fn write_reconstruction_set(out: &Path, solved: Solved, set: OutputSet) -> Result<Vec<PathBuf>, IoError> {
    let Solved { reconstruction: rec, cfg, params, inputs, prepared, seconds } = solved;
    std::fs::create_dir_all(out).map_err(|source| IoError::Os { path: out.to_path_buf(), action: "create folder", source })?;
    let mut files = Vec::new();
    let path = |name: &str| out.join(name);
    let full = set == OutputSet::Full;

    let v = rec.video.view();
    let frame_time_us = (!cfg.timing().is_still()).then_some(rec.frame_time_us);
    if let Some(display) = write_video_files(out, v, frame_time_us, set, &mut files)? {
        let delay_ms = 80;
        io::write_gif(path("video.gif"), v, &display, delay_ms, frame_time_us)?;
        files.push(path("video.gif"));
    }

    // The static + dynamic model's parts: the static image, and the dynamic video
    // (video.npy stays their sum).
    if let Some(sb) = &rec.static_background {
        if full {
            io::write_tiff_f32(path("static.tiff"), sb.image.view())?;
            files.push(path("static.tiff"));
        }
        let (r, c, ch) = sb.image.dim();
        io::write_stack(path("static.npy"), sb.image.view().into_shape_with_order((1, r, c, ch)).expect("one frame"))?;
        files.push(path("static.npy"));
        io::write_stack(path("dynamic.npy"), sb.dynamic(&rec.video).view())?;
        files.push(path("dynamic.npy"));
    }

    if set != OutputSet::Minimal {
        let traces: Vec<(usize, &[trace::TraceRow])> = rec.channels.iter().map(|c| (c.channel, c.trace.as_slice())).collect();
        let csv = trace::to_csv(&traces);
        io::write_text_atomic(&path("trace.csv"), &csv)?;
        files.push(path("trace.csv"));
    }
    if full {
        let plot = trace_plot(rec);
        io::plot_lines(path("trace.png"), &plot)?;
        files.push(path("trace.png"));
        io::plot_lines(path("trace.svg"), &plot)?;
        files.push(path("trace.svg"));
    }

    let mut names: Vec<String> = files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    names.push("summary.json".into());
    let summary = Summary::new(rec, cfg, params, inputs, prepared, seconds, names);
    let json = serde_json::to_string_pretty(&summary).expect("summary serialises");
    io::write_text_atomic(&path("summary.json"), &json)?;
    files.push(path("summary.json"));
    Ok(files)
}

/// Error against run time when a truth is known (PSNR), else objective against time.
fn trace_plot(rec: &Reconstruction) -> PlotSpec {
    let with_truth = rec.channels.iter().any(|c| c.stats.error.is_some());
    // The solver that ran (fista-restart, admm, ...), and the channel when there are several.
    let label = |c: &crate::solve::channel::ChannelReport| {
        if rec.channels.len() == 1 {
            c.solver.name().to_string()
        } else {
            format!("channel {} ({})", c.channel, c.solver.name())
        }
    };
    let series = rec
        .channels
        .iter()
        .map(|c| Series {
            name: label(c),
            points: c
                .trace
                .iter()
                .filter_map(|r| {
                    let y = if with_truth { r.psnr_db? } else { r.objective };
                    y.is_finite().then_some((r.seconds, y))
                })
                .collect(),
        })
        .collect();
    PlotSpec {
        title: if with_truth { "Error against run time".into() } else { "Objective against run time".into() },
        x_label: "solver time (s)".into(),
        y_label: if with_truth { "PSNR against truth (dB)".into() } else { "objective 0.5||Av-b||^2 + tau TV(v)".into() },
        series,
        log_y: !with_truth,
        ..PlotSpec::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_sets_parse_from_their_names() {
        for set in OutputSet::ALL {
            assert_eq!(set.to_string().parse::<OutputSet>(), Ok(set));
            assert_eq!(serde_json::to_value(set).unwrap(), set.name());
        }
        assert_eq!(OutputSet::default(), OutputSet::Full);
        let err = "gifs".parse::<OutputSet>().unwrap_err();
        assert!(err.contains("gifs") && err.contains("full, video or minimal"), "{err}");
    }
}
