//! The folder a sequence reconstruction writes: `video.tiff` (float32 stack),
//! `video.npy`, `contact.png`, `trace.csv` (one block per solve), `coverage.csv` (per
//! video frame: time, exposure weight, gap flag, captures) and `summary.json`, last,
//! so its presence means the folder is complete. Every file is written atomically.

use crate::io::sequence_input::Skipped;
use crate::io::{self, IoError};
use crate::model::capture::CaptureConfig;
use crate::model::prepare::SensorReport;
use crate::model::time_grid::TimeGrid;
use crate::solve::reconstruct::SolveParams;
use crate::solve::sequence::solve::{Mode, SequenceVideo, SolveReport};
use crate::solve::trace;
use ndarray::ArrayView4;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// One capture of the sequence, as the summary records it.
#[derive(Clone, Debug, Serialize)]
pub struct CaptureEntry {
    pub file: String,
    pub sequence: u64,
    /// First-row exposure start relative to the first capture, microseconds.
    pub start_us: f64,
    /// First video frame.
    pub offset_frames: usize,
    /// `start_us - offset_frames * frame_time_us`.
    pub residue_us: f64,
    pub dark_level: f64,
}

impl CaptureEntry {
    /// One entry per capture of `grid`: its file, sequence number and dark level, and
    /// where the grid placed it.
    pub fn list(grid: &TimeGrid, files: &[String], sequence: &[u64], dark_level: &[f64]) -> Vec<CaptureEntry> {
        (0..grid.captures())
            .map(|c| CaptureEntry {
                file: files[c].clone(),
                sequence: sequence[c],
                start_us: grid.start_us[c],
                offset_frames: grid.offsets[c],
                residue_us: grid.residue_us[c],
                dark_level: dark_level[c],
            })
            .collect()
    }
}

/// Everything `summary.json` of a sequence records.
#[derive(Serialize)]
pub struct SequenceSummary<'a> {
    pub rollcam_version: &'static str,
    pub capture_dir: String,
    pub psf: String,
    pub config: String,
    pub truth: Option<String>,
    pub capture: &'a CaptureConfig,
    pub params: &'a SolveParams,
    pub mode: Mode,
    /// Streaming overlap, frames (streaming only).
    pub overlap_frames: Option<usize>,
    /// How the captures were placed in time (device timestamps or a frame period).
    pub time_source: crate::model::time_grid::TimeSource,
    /// Mean spacing of the device timestamps per sequence number, microseconds.
    pub timestamp_period_us: Option<f64>,
    /// Largest rounding residue of a capture start onto the grid, microseconds.
    pub max_residue_us: f64,
    /// (frames, rows, cols, channels) of the video.
    pub video_shape: [usize; 4],
    pub frame_time_us: f64,
    pub frames_per_second: f64,
    pub frames_per_capture: usize,
    pub captures: Vec<CaptureEntry>,
    pub skipped: &'a [Skipped],
    /// Video frames no capture covers (only the temporal TV constrains them).
    pub gap_frames: Vec<usize>,
    /// Video frames two or more captures cover.
    pub shared_frames: Vec<usize>,
    /// Per video frame: exposure weight summed over captures and sensor rows.
    pub coverage: &'a [f64],
    pub psf_dark_level: f64,
    pub dark_level_estimated: bool,
    /// The bench calibration folder and background frame, when used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub background: Option<String>,
    /// Per capture: what sensor handling did (dark source, clipped and defective
    /// pixels, the data term's mask, warnings).
    pub sensor: &'a [SensorReport],
    pub solves: &'a [SolveReport],
    /// Wall seconds of all solves.
    pub seconds: f64,
    pub joint_memory_bytes: usize,
    pub psnr_db: Option<f64>,
    pub rel_error: Option<f64>,
    pub files: Vec<String>,
}

/// `coverage.csv`: frame, start time, coverage, gap flag, the captures that cover it.
pub fn coverage_csv(grid: &TimeGrid) -> String {
    let mut s = String::from("frame,start_us,coverage,gap,captures\n");
    for f in 0..grid.frames {
        let caps: Vec<String> = (0..grid.captures()).filter(|&c| grid.frames_of(c).contains(&f)).map(|c| c.to_string()).collect();
        s.push_str(&format!("{f},{:.3},{:.6},{},{}\n", f as f64 * grid.frame_time_us, grid.coverage[f], u8::from(grid.coverage[f] == 0.0), caps.join(" ")));
    }
    s
}

/// Write the folder; `summary` gets its `files` list filled here. Returns the files.
pub fn write_sequence(out: &Path, rec: &SequenceVideo, grid: &TimeGrid, summary: SequenceSummary) -> Result<Vec<PathBuf>, IoError> {
    write_sequence_with(out, rec, grid, summary, serde_json::Map::new(), crate::io::output::OutputSet::Full)
}

/// Every file a sequence folder may get (for the output-folder check).
pub const SEQUENCE_FILES: &[&str] =
    &["video.tiff", "video.npy", "contact.png", "video.gif", "trace.csv", "trace.png", "trace.svg", "coverage.csv", "summary.json"];

/// [`write_sequence`] with the files of `set` (`full`: all; else no TIFF stack and no
/// contact sheet) and `extra` fields added to `summary.json` (a live stream's
/// progress, say).
pub fn write_sequence_with(
    out: &Path,
    rec: &SequenceVideo,
    grid: &TimeGrid,
    mut summary: SequenceSummary,
    extra: serde_json::Map<String, serde_json::Value>,
    set: crate::io::output::OutputSet,
) -> Result<Vec<PathBuf>, IoError> {
    std::fs::create_dir_all(out).map_err(|source| IoError::Os { path: out.to_path_buf(), action: "create folder", source })?;
    let (k, m, n) = rec.shape;
    let v = ArrayView4::from_shape((k, m, n, 1), &rec.video).expect("video shape");
    let mut files = Vec::new();
    let path = |name: &str| out.join(name);
    crate::io::output::write_video_files(out, v, Some(grid.frame_time_us), set, &mut files)?;
    let traces: Vec<(usize, &[trace::TraceRow])> = rec.solves.iter().enumerate().map(|(i, s)| (i, s.trace.as_slice())).collect();
    io::write_text_atomic(&path("trace.csv"), &trace::to_csv(&traces))?;
    files.push(path("trace.csv"));
    io::write_text_atomic(&path("coverage.csv"), &coverage_csv(grid))?;
    files.push(path("coverage.csv"));
    let mut names: Vec<String> = files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    names.push("summary.json".into());
    summary.files = names;
    let json = if extra.is_empty() {
        serde_json::to_string_pretty(&summary).expect("summary serialises")
    } else {
        let mut value = serde_json::to_value(&summary).expect("summary serialises");
        if let Some(obj) = value.as_object_mut() {
            obj.extend(extra);
        }
        serde_json::to_string_pretty(&value).expect("summary serialises")
    };
    io::write_text_atomic(&path("summary.json"), &json)?;
    files.push(path("summary.json"));
    Ok(files)
}
