//! `analyze`: every measurement of one video against what its timing predicts, written
//! as PNG images, SVG/PNG plots and `analysis.json`.

use super::spectrum::{power_spectrum, Spectrum};
use super::theory::{exposure_transfer, Theory, WaveformTheory};
use super::video::{dip_between, find_spots, fundamental_contrast, neighbour_pairs, projections, temporal_contrast, time_sum, Dip, Spot};
use crate::io::{self, Display, IoError, PlotSpec, Series};
use crate::model::capture::CaptureConfig;
use ndarray::{Array2, Array3, ArrayView4};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Errors of the analysis, each naming the input and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    #[error("{what}: {problem}")]
    Input { what: String, problem: String },
    #[error(transparent)]
    Io(#[from] IoError),
}

fn input_err(what: impl Into<String>, problem: impl Into<String>) -> AnalysisError {
    AnalysisError::Input { what: what.into(), problem: problem.into() }
}

/// A rectangle of the video: rows `r0..r1`, columns `c0..c1` (ends excluded).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Region {
    pub r0: usize,
    pub r1: usize,
    pub c0: usize,
    pub c1: usize,
}

impl std::str::FromStr for Region {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let v: Vec<usize> = s
            .split(',')
            .map(|x| x.trim().parse::<usize>())
            .collect::<Result<_, _>>()
            .map_err(|e| format!("region '{s}': {e}: expected r0,r1,c0,c1 (four non-negative integers)"))?;
        if v.len() != 4 {
            return Err(format!("region '{s}': {} numbers, expected r0,r1,c0,c1 (four)", v.len()));
        }
        Ok(Region { r0: v[0], r1: v[1], c0: v[2], c1: v[3] })
    }
}

impl Region {
    /// A square of half-width `radius` around a pixel, clipped to `rows x cols`.
    pub fn around(row: usize, col: usize, radius: usize, rows: usize, cols: usize) -> Region {
        Region { r0: row.saturating_sub(radius), r1: (row + radius + 1).min(rows), c0: col.saturating_sub(radius), c1: (col + radius + 1).min(cols) }
    }

    pub fn check(&self, name: &str, rows: usize, cols: usize) -> Result<(), AnalysisError> {
        let what = format!("{name} (r0,r1,c0,c1 = {},{},{},{})", self.r0, self.r1, self.c0, self.c1);
        if self.r0 >= self.r1 || self.c0 >= self.c1 {
            return Err(input_err(what, "empty: expected r0 < r1 and c0 < c1 (ends excluded)"));
        }
        if self.r1 > rows || self.c1 > cols {
            return Err(input_err(what, format!("outside the video's frame of {rows} rows x {cols} columns")));
        }
        Ok(())
    }

    /// Sum over the region (mean over channels) for every frame.
    pub fn time_course(&self, video: ArrayView4<f32>) -> Vec<f64> {
        let (k, _, _, c) = video.dim();
        (0..k)
            .map(|f| {
                let mut s = 0.0f64;
                for r in self.r0..self.r1 {
                    for col in self.c0..self.c1 {
                        for ch in 0..c {
                            s += video[[f, r, col, ch]] as f64;
                        }
                    }
                }
                s / c as f64
            })
            .collect()
    }
}

/// Capture timing a video needs for its frequency axis.
#[derive(Clone, Debug, Serialize)]
pub struct VideoTiming {
    pub frame_time_us: f64,
    pub exposure_us: f64,
    /// Rows x cols of the rolling-shutter samples (the downsampled sensor).
    pub grid: (usize, usize),
    /// Span of the capture's row starts plus one line time, microseconds.
    pub record_us: f64,
    /// Spatial downsampling of the video against the raw sensor.
    pub downsample: usize,
    /// Where the timing came from.
    pub source: String,
}

impl VideoTiming {
    pub fn from_config(cfg: &CaptureConfig, frame_time_us: Option<f64>, source: &str) -> Result<VideoTiming, AnalysisError> {
        cfg.validate().map_err(|e| input_err(source, e.to_string()))?;
        let t = cfg.timing();
        let starts = t.raw_row_starts_us();
        let span = starts.iter().cloned().fold(0.0f64, f64::max);
        let frame_time_us = frame_time_us.unwrap_or_else(|| t.frame_time_us());
        if !(frame_time_us.is_finite() && frame_time_us > 0.0) {
            return Err(input_err(source, format!("frame_time_us = {frame_time_us}: expected a positive time in microseconds")));
        }
        Ok(VideoTiming {
            frame_time_us,
            exposure_us: cfg.exposure_us,
            grid: cfg.grid(),
            record_us: span + cfg.line_time_us,
            downsample: cfg.downsample,
            source: source.to_string(),
        })
    }

    /// The timing recorded in a reconstruction folder's `summary.json`.
    pub fn from_summary(path: &Path) -> Result<VideoTiming, AnalysisError> {
        let what = path.display().to_string();
        let text = crate::io::input::read_text(path).map_err(|e| input_err(&what, format!("cannot read: {e}")))?;
        let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| input_err(&what, format!("not JSON: {e}")))?;
        let ft = v
            .get("frame_time_us")
            .and_then(|x| x.as_f64())
            .ok_or_else(|| input_err(&what, "no frame_time_us: expected the frame time in microseconds (give --config capture.toml instead)"))?;
        let cap = v.get("capture").ok_or_else(|| input_err(&what, "no capture table: expected the capture's timing (give --config capture.toml instead)"))?;
        let cfg: CaptureConfig =
            serde_json::from_value(cap.clone()).map_err(|e| input_err(format!("{what}: capture"), format!("{e}: expected a capture description")))?;
        VideoTiming::from_config(&cfg, Some(ft), &what)
    }
}

/// Sensor geometry for angles.
#[derive(Clone, Debug, Serialize)]
pub struct Geometry {
    /// Diffuser-to-sensor distance, millimetres.
    pub distance_mm: f64,
    /// Raw pixel pitch, micrometres.
    pub pixel_pitch_um: f64,
    /// Object-to-diffuser distance, millimetres (for separations at the object).
    pub object_distance_mm: Option<f64>,
}

#[derive(Clone, Debug)]
pub struct AnalyzeOptions {
    /// Regions to analyse; empty: the brightest spots, found automatically.
    pub regions: Vec<Region>,
    pub waveform_period_us: Option<f64>,
    pub duty: f64,
    pub max_spots: usize,
    /// Half-width of the square region around each spot, pixels.
    pub spot_radius: usize,
    /// Spots below this fraction of the brightest (above background) are ignored.
    pub spot_threshold: f64,
    /// Frames dropped at each end before the temporal analysis.
    pub trim_frames: usize,
    pub geometry: Option<Geometry>,
}

impl Default for AnalyzeOptions {
    fn default() -> Self {
        AnalyzeOptions {
            regions: Vec::new(),
            waveform_period_us: None,
            duty: 0.5,
            max_spots: 8,
            spot_radius: 1,
            spot_threshold: 0.2,
            trim_frames: 0,
            geometry: None,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct RegionReport {
    pub name: String,
    pub region: Region,
    /// Mean of the time course.
    pub mean: f64,
    /// Michelson contrast of the 5th/95th percentiles of the time course.
    pub temporal_contrast: f64,
    /// Fundamental contrast at the waveform frequency (with a waveform period).
    pub fundamental_contrast: Option<f64>,
    pub peak_frequency_hz: Option<f64>,
    #[serde(skip)]
    pub course: Vec<f64>,
    #[serde(skip)]
    pub spectrum: Spectrum,
}

#[derive(Clone, Debug, Serialize)]
pub struct Angular {
    /// Angle one video pixel subtends: atan(pitch * downsample / distance), degrees.
    pub degrees_per_pixel: f64,
    /// Smallest separation of two spots that are resolved, pixels and degrees.
    pub smallest_resolved_px: Option<f64>,
    pub smallest_resolved_deg: Option<f64>,
    /// That separation at the object, millimetres (with an object distance).
    pub smallest_resolved_mm: Option<f64>,
}

/// Measurement beside theory for a waveform.
#[derive(Clone, Debug, Serialize)]
pub struct Verdict {
    pub expected_frequency_hz: f64,
    pub measured_peak_hz: Option<f64>,
    /// Native bin width of the spectrum, Hz.
    pub bin_hz: f64,
    pub peak_within_one_bin: bool,
    /// Mean over the regions of the fundamental contrast (1: a full square wave).
    pub fundamental_contrast: f64,
    /// `|sinc(f0 T_e)|`: what the exposure leaves of the fundamental.
    pub expected_fundamental_contrast: f64,
    /// Mean over the regions of the Michelson contrast of the 5th/95th percentiles.
    pub temporal_contrast: f64,
    /// Exact Michelson contrast of the square wave after the exposure's box mean.
    pub expected_contrast_after_exposure: f64,
    /// Plain-language notes where measurement and theory agree or disagree.
    pub notes: Vec<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Analysis {
    pub video_shape: [usize; 4],
    pub timing: VideoTiming,
    pub theory: Theory,
    pub frames_analysed: (usize, usize),
    pub spots: Vec<Spot>,
    pub regions: Vec<RegionReport>,
    /// Peak of the summed spectra of all regions.
    pub combined_peak_hz: Option<f64>,
    pub bin_hz: f64,
    pub dips: Vec<Dip>,
    pub angular: Option<Angular>,
    pub verdict: Option<Verdict>,
    pub files: Vec<String>,
    #[serde(skip)]
    pub combined: Option<Spectrum>,
    #[serde(skip)]
    pub projection_spectrum: Option<Spectrum>,
}

/// Measure `video` (frame, row, col, channel) with `timing`.
pub fn analyze_video(video: ArrayView4<f32>, timing: &VideoTiming, opts: &AnalyzeOptions) -> Result<Analysis, AnalysisError> {
    let (k, m, n, c) = video.dim();
    let (f0, f1) = check_video(video, timing, opts)?;
    let tf = timing.frame_time_us;
    let theory = Theory::new(tf, timing.exposure_us, opts.waveform_period_us.map(|p| (p, opts.duty)), Some((timing.grid.0, timing.grid.1, timing.record_us)));

    let summed = time_sum(video);
    let spots = find_spots(&summed, 2, opts.spot_threshold, opts.max_spots);
    let regions = measure_regions(video, &spots, opts, (f0, f1), tf)?;
    let combined = Spectrum::sum(regions.iter().map(|r| &r.spectrum));
    let combined_peak_hz = combined.as_ref().and_then(|s| s.peak().map(|p| p.0));
    let bin_hz = 1e6 / ((f1 - f0) as f64 * tf);

    // Spectrum of the x-t projection: the power spectra of its columns, summed.
    let proj = projections(video);
    let col_spectra: Vec<Spectrum> = (0..n).map(|col| power_spectrum(&proj.xt_sum.column(col).to_vec()[f0..f1], tf)).collect();
    let projection_spectrum = Spectrum::sum(col_spectra.iter());

    let pairs = neighbour_pairs(&spots);
    let dips: Vec<Dip> = pairs.iter().map(|&(i, j)| dip_between(&summed, (spots[i].row, spots[i].col), (spots[j].row, spots[j].col))).collect();
    let angular = opts.geometry.as_ref().map(|g| angular_resolution(g, timing.downsample, &dips));
    let verdict = theory.waveform.as_ref().map(|w| waveform_verdict(w, theory.band_limit_hz, &regions, combined_peak_hz, bin_hz));

    Ok(Analysis {
        video_shape: [k, m, n, c],
        timing: timing.clone(),
        theory,
        frames_analysed: (f0, f1),
        spots,
        regions,
        combined_peak_hz,
        bin_hz,
        dips,
        angular,
        verdict,
        files: Vec::new(),
        combined,
        projection_spectrum,
    })
}

/// Refuses a video too short, empty or not finite, a waveform period or duty out of
/// range, and a trim that leaves fewer than 4 frames; returns the frames analysed
/// (`f0..f1`).
fn check_video(video: ArrayView4<f32>, timing: &VideoTiming, opts: &AnalyzeOptions) -> Result<(usize, usize), AnalysisError> {
    let (k, m, n, c) = video.dim();
    if k < 4 {
        return Err(input_err("video", format!("{k} frames: expected at least 4 for a temporal analysis")));
    }
    if c == 0 || m == 0 || n == 0 {
        return Err(input_err("video", format!("shape {k} x {m} x {n} x {c}: expected non-empty frames")));
    }
    if let Some((i, v)) = video.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        let (f, r) = (i / (m * n * c), i / (n * c) % m);
        return Err(input_err("video", format!("a value of {v} at frame {f}, row {r}, col {}: expected finite values", i / c % n)));
    }
    let record_us = k as f64 * timing.frame_time_us;
    if let Some(p) = opts.waveform_period_us {
        // Longer than 100 records, the wave's fundamental lies far below the spectrum's
        // first bin (and its harmonics up to the frame rate number in the millions).
        // Shorter than a hundredth of a frame, its fundamental lies 100 frame rates up:
        // no exposure passes it (and 1e-320 us printed as "inf Hz").
        if !(p.is_finite() && p >= 0.01 * timing.frame_time_us && p <= 100.0 * record_us) {
            return Err(input_err(
                "waveform period (--waveform-period-us)",
                format!(
                    "{p} us: expected a positive period in microseconds, from a hundredth of a frame ({} us) to at most 100 times the video's {k} frames x {} us",
                    0.01 * timing.frame_time_us,
                    timing.frame_time_us
                ),
            ));
        }
        if !(opts.duty > 0.0 && opts.duty < 1.0) {
            return Err(input_err(
                "duty (--duty)",
                format!("{}: expected a duty cycle between 0 and 1 (the fraction of each period the wave is on)", opts.duty),
            ));
        }
    }
    if opts.regions.is_empty() && opts.max_spots == 0 {
        return Err(input_err("most spots (--max-spots)", "0 with no --region: expected at least 1 spot to analyse, or regions given with --region"));
    }
    let (f0, f1) = (opts.trim_frames, k.saturating_sub(opts.trim_frames));
    if f1 < f0 + 4 {
        return Err(input_err("trim frames", format!("{} at each end of {k} frames leaves fewer than 4", opts.trim_frames)));
    }
    Ok((f0, f1))
}

/// The regions measured: the ones given (checked against the frame), else a square of
/// `opts.spot_radius` around each bright spot found; each region's time course over
/// frames `f0..f1` (frame time `tf` us), its contrasts and spectrum.
fn measure_regions(
    video: ArrayView4<f32>,
    spots: &[Spot],
    opts: &AnalyzeOptions,
    (f0, f1): (usize, usize),
    tf: f64,
) -> Result<Vec<RegionReport>, AnalysisError> {
    let (_, m, n, _) = video.dim();
    let mut named: Vec<(String, Region)> = Vec::new();
    if opts.regions.is_empty() {
        for (i, s) in spots.iter().enumerate() {
            named.push((format!("spot {i} ({}, {})", s.row, s.col), Region::around(s.row, s.col, opts.spot_radius, m, n)));
        }
        if named.is_empty() {
            return Err(input_err("video", "no bright spot above the background: give --region r0,r1,c0,c1"));
        }
    } else {
        for (i, r) in opts.regions.iter().enumerate() {
            let name = format!("region {i}");
            r.check(&name, m, n)?;
            named.push((name, *r));
        }
    }
    Ok(named
        .into_iter()
        .map(|(name, region)| {
            let full = region.time_course(video);
            let course = full[f0..f1].to_vec();
            let spectrum = power_spectrum(&course, tf);
            RegionReport {
                name,
                region,
                mean: course.iter().sum::<f64>() / course.len() as f64,
                temporal_contrast: temporal_contrast(&course),
                fundamental_contrast: opts.waveform_period_us.map(|p| fundamental_contrast(&course, tf, 1e6 / p, opts.duty)),
                peak_frequency_hz: spectrum.peak().map(|p| p.0),
                course,
                spectrum,
            }
        })
        .collect())
}

/// The angle one video pixel subtends (pixels of the sensor binned by `downsample`) and
/// the smallest separation among the resolved spot pairs, in pixels, degrees and, with
/// an object distance, millimetres.
fn angular_resolution(g: &Geometry, downsample: usize, dips: &[Dip]) -> Angular {
    let deg_px = (g.pixel_pitch_um * 1e-3 * downsample as f64 / g.distance_mm).atan().to_degrees();
    let smallest = dips.iter().filter(|d| d.resolved).map(|d| d.separation_px).fold(None, |a: Option<f64>, s| Some(a.map_or(s, |a| a.min(s))));
    let deg = smallest.map(|s| s * deg_px);
    Angular {
        degrees_per_pixel: deg_px,
        smallest_resolved_px: smallest,
        smallest_resolved_deg: deg,
        smallest_resolved_mm: deg.and_then(|d| g.object_distance_mm.map(|z| z * d.to_radians().tan())),
    }
}

/// The measurement beside the theory of waveform `w` (band limit `band_limit_hz`): the
/// combined spectral peak against the waveform frequency (within one bin of `bin_hz`),
/// and the regions' mean fundamental contrast against what the exposure leaves, each
/// with a note in plain language.
fn waveform_verdict(w: &WaveformTheory, band_limit_hz: f64, regions: &[RegionReport], combined_peak_hz: Option<f64>, bin_hz: f64) -> Verdict {
    let measured = combined_peak_hz;
    let within = measured.is_some_and(|f| (f - w.frequency_hz).abs() <= bin_hz);
    let contrast = regions.iter().map(|r| r.temporal_contrast).sum::<f64>() / regions.len() as f64;
    let fundamental = regions.iter().filter_map(|r| r.fundamental_contrast).sum::<f64>() / regions.len() as f64;
    let mut notes = Vec::new();
    match (w.resolvable, within) {
        (true, true) => notes.push(format!(
            "agrees: the spectral peak ({:.0} Hz) lies within one bin ({bin_hz:.0} Hz) of the waveform frequency {:.0} Hz, below the band limit {:.0} Hz",
            measured.unwrap(),
            w.frequency_hz,
            band_limit_hz
        )),
        (true, false) => notes.push(format!(
            "disagrees: theory resolves {:.0} Hz (below the band limit {:.0} Hz) but the spectral peak is at {} Hz, more than one bin ({bin_hz:.0} Hz) away",
            w.frequency_hz,
            band_limit_hz,
            measured.map_or("no".into(), |f| format!("{f:.0}"))
        )),
        (false, true) => {
            notes.push(format!("disagrees: {:.0} Hz is at or beyond the band limit {:.0} Hz, yet the spectrum peaks there", w.frequency_hz, band_limit_hz))
        }
        (false, false) => {
            notes.push(format!("agrees: {:.0} Hz is at or beyond the band limit {:.0} Hz and the spectrum shows no peak there", w.frequency_hz, band_limit_hz))
        }
    }
    let expected = w.fundamental_transfer;
    let ideal = w.frame_fundamental_transfer;
    if expected < 0.05 {
        if fundamental < 0.25 {
            notes.push(format!("agrees: the exposure leaves |sinc(f0 T_e)| = {expected:.2} of the fundamental in the raw rows, and the reconstruction's fundamental contrast collapsed to {fundamental:.2}"));
        } else {
            notes.push(format!("disagrees: the raw rows carry |sinc(f0 T_e)| = {expected:.2} of the fundamental, yet the reconstruction shows a fundamental contrast of {fundamental:.2} (modulation the measurement cannot hold: regulariser or model artefact)"));
        }
    } else if fundamental >= expected - 0.15 {
        notes.push(format!(
            "agrees: fundamental contrast {fundamental:.2} against {expected:.2} = |sinc(f0 T_e)| in the raw rows{} (the model knows the exposure window and can undo its attenuation up to the frame-limited |sinc(f0 T_f)| = {ideal:.2})",
            if fundamental > expected + 0.05 { ", recovered above it" } else { "" }
        ));
    } else {
        notes.push(format!("below theory: fundamental contrast {fundamental:.2} against {expected:.2} = |sinc(f0 T_e)| that the raw rows carry (the reconstruction loses modulation the measurement holds)"));
    }
    Verdict {
        expected_frequency_hz: w.frequency_hz,
        measured_peak_hz: measured,
        bin_hz,
        peak_within_one_bin: within,
        fundamental_contrast: fundamental,
        expected_fundamental_contrast: expected,
        temporal_contrast: contrast,
        expected_contrast_after_exposure: w.contrast_after_exposure,
        notes,
    }
}

/// Nearest-neighbour upscaling so the shorter side reaches `min_side` pixels.
pub fn upscale(img: &Array2<f64>, min_side: usize) -> Array2<f64> {
    let (m, n) = img.dim();
    let s = min_side.div_ceil(m.min(n).max(1)).max(1);
    Array2::from_shape_fn((m * s, n * s), |(r, c)| img[[r / s, c / s]])
}

/// Write a 2-D map as a grey PNG (0.1/99.9 percentile display), upscaled for viewing.
pub fn write_map_png(path: &Path, img: &Array2<f64>, min_side: usize) -> Result<(), IoError> {
    let up = upscale(img, min_side);
    let (m, n) = up.dim();
    let data: Array3<f32> = Array3::from_shape_fn((m, n, 1), |(r, c, _)| up[[r, c]] as f32);
    let display = Display::auto(data.iter(), 0.1, 99.9);
    io::write_png(path, data.view(), &display)
}

fn normalised(points: impl Iterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    let p: Vec<(f64, f64)> = points.collect();
    let top = p.iter().map(|q| q.1).fold(0.0f64, f64::max);
    p.into_iter().map(|(x, y)| (x, if top > 0.0 { y / top } else { 0.0 })).collect()
}

/// A comb of vertical unit lines at `xs`.
fn comb(xs: &[f64]) -> Vec<(f64, f64)> {
    let mut v = Vec::new();
    for &x in xs {
        v.extend([(x, 0.0), (x, 1.0), (x, 0.0)]);
    }
    v
}

/// The spectrum plot: the combined spectrum of the regions and of the x-t projection
/// (each normalised), the exposure's |sinc|^2, the band limits and the waveform's
/// harmonics.
pub fn spectrum_plot(a: &Analysis, title: &str) -> PlotSpec {
    let th = &a.theory;
    let mut series = Vec::new();
    if let Some(s) = &a.combined {
        series.push(Series { name: "regions (sum of power spectra)".into(), points: normalised(s.frequency_hz.iter().cloned().zip(s.power.iter().cloned())) });
    }
    if let Some(s) = &a.projection_spectrum {
        series.push(Series { name: "x-t projection".into(), points: normalised(s.frequency_hz.iter().cloned().zip(s.power.iter().cloned())) });
    }
    let nyq = th.nyquist_hz;
    series.push(Series {
        name: format!("exposure |sinc(f Te)|^2, Te = {:.0} us", th.exposure_us),
        points: (0..=200)
            .map(|i| {
                let f = nyq * i as f64 / 200.0;
                (f, exposure_transfer(f, th.exposure_us).powi(2))
            })
            .collect(),
    });
    series.push(Series {
        name: format!("1/Te = {:.0} Hz, Nyquist = {:.0} Hz", th.exposure_first_zero_hz, nyq),
        points: comb(&[th.exposure_first_zero_hz.min(nyq), nyq]),
    });
    if let Some(w) = &th.waveform {
        let fs: Vec<f64> = w.harmonics.iter().map(|h| h.observed_hz).filter(|f| *f <= nyq).collect();
        series.push(Series { name: format!("square wave {:.0} us: f0 = {:.0} Hz and odd harmonics", w.period_us, w.frequency_hz), points: comb(&fs) });
    }
    PlotSpec { title: title.into(), x_label: "temporal frequency (Hz)".into(), y_label: "power (normalised)".into(), series, ..PlotSpec::default() }
}

fn timecourse_plot(a: &Analysis) -> PlotSpec {
    let tf = a.timing.frame_time_us;
    let f0 = a.frames_analysed.0;
    let series = a
        .regions
        .iter()
        .take(6)
        .map(|r| Series { name: r.name.clone(), points: normalised(r.course.iter().enumerate().map(|(i, &v)| ((f0 + i) as f64 * tf * 1e-3, v))) })
        .collect();
    PlotSpec {
        title: "Time courses of the regions".into(),
        x_label: "time (ms)".into(),
        y_label: "region sum (normalised)".into(),
        series,
        ..PlotSpec::default()
    }
}

/// Every file `analyze` may write into its folder (for the output-folder check).
pub const ANALYSIS_FILES: &[&str] = &[
    "xt_max.png",
    "xt_sum.png",
    "yt_max.png",
    "yt_sum.png",
    "time_sum.png",
    "spectrum.svg",
    "spectrum.png",
    "timecourse.svg",
    "timecourse.png",
    "analysis.json",
    "track.json",
];

/// Write the images, plots and `analysis.json` into `out`; returns the analysis with
/// its file list.
pub fn write_analysis(out: &Path, video: ArrayView4<f32>, mut a: Analysis) -> Result<Analysis, AnalysisError> {
    std::fs::create_dir_all(out).map_err(|source| IoError::Os { path: out.to_path_buf(), action: "create folder", source })?;
    let mut files: Vec<PathBuf> = Vec::new();
    let p = projections(video);
    for (name, img) in [("xt_max.png", &p.xt_max), ("xt_sum.png", &p.xt_sum), ("yt_max.png", &p.yt_max), ("yt_sum.png", &p.yt_sum)] {
        write_map_png(&out.join(name), img, 256)?;
        files.push(out.join(name));
    }
    write_map_png(&out.join("time_sum.png"), &time_sum(video), 256)?;
    files.push(out.join("time_sum.png"));
    let title = match &a.theory.waveform {
        Some(w) => format!("Temporal power spectrum (square wave {:.0} us)", w.period_us),
        None => "Temporal power spectrum".into(),
    };
    let spec = spectrum_plot(&a, &title);
    let tc = timecourse_plot(&a);
    for ext in ["svg", "png"] {
        io::plot_lines(out.join(format!("spectrum.{ext}")), &spec)?;
        io::plot_lines(out.join(format!("timecourse.{ext}")), &tc)?;
        files.push(out.join(format!("spectrum.{ext}")));
        files.push(out.join(format!("timecourse.{ext}")));
    }
    files.push(out.join("analysis.json"));
    a.files = files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect();
    let json = serde_json::to_string_pretty(&a).expect("analysis serialises");
    let path = out.join("analysis.json");
    io::write_text_atomic(&path, &json)?;
    Ok(a)
}
