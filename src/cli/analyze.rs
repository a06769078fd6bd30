//! `rollcam analyze`: x-t / y-t projections, temporal power spectra in Hz, theory beside
//! measurement, spatial dips, written as images, plots and `analysis.json`.

use anyhow::{bail, Context, Result};
use clap::Args;
use rollcam::analysis::input::resolve_input;
use rollcam::analysis::report::{analyze_video, write_analysis, AnalyzeOptions, Geometry, Region};
use rollcam::io;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct AnalyzeArgs {
    /// Reconstruction folder (video.npy or video.tiff, and summary.json with the timing).
    pub rec_dir: Option<PathBuf>,
    /// A video file (.npy, multi-page TIFF, or a folder of images) instead of a folder;
    /// needs --config.
    #[arg(long)]
    pub video: Option<PathBuf>,
    /// capture.toml with the timing (overrides summary.json's).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Region rows r0..r1, columns c0..c1 (ends excluded); repeat for more. Default: the
    /// brightest spots of the time-summed video.
    #[arg(long, value_name = "r0,r1,c0,c1")]
    pub region: Vec<Region>,
    /// Period of a square-wave waveform in the scene, microseconds: marks its
    /// fundamental and harmonics and compares with the theory.
    #[arg(long)]
    pub waveform_period_us: Option<f64>,
    /// Duty cycle of that waveform.
    #[arg(long, default_value_t = 0.5)]
    pub duty: f64,
    /// Most spots analysed automatically.
    #[arg(long, default_value_t = 8)]
    pub max_spots: usize,
    /// Frames dropped at each end before the temporal analysis.
    #[arg(long, default_value_t = 0)]
    pub trim_frames: usize,
    /// Diffuser-to-sensor distance, millimetres (with --pixel-pitch-um: angles).
    #[arg(long)]
    pub distance_mm: Option<f64>,
    /// Raw pixel pitch, micrometres.
    #[arg(long)]
    pub pixel_pitch_um: Option<f64>,
    /// Object-to-diffuser distance, millimetres (separations at the object).
    #[arg(long)]
    pub object_distance_mm: Option<f64>,
    /// Output folder (default: REC_DIR/analysis, or beside the video): new or empty
    /// (or see --force).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub force: crate::cli::common::ForceFlag,
    /// Truth video of a simulated moving object over a still scene (truth.npy): track
    /// the object in both (the middle 70% of the frames) and compare the still scenes
    /// (the reconstruction's static.npy when it has one, else the per-pixel temporal
    /// median); writes track.json.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Radius of the window around each frame's brightest excess where the object's
    /// centroid is taken, pixels of the video grid.
    #[arg(long, default_value_t = 12.0)]
    pub track_radius_px: f64,
}

/// What `--truth` measures: the object's track and the still scene.
#[derive(serde::Serialize)]
struct TrackSummary {
    video: String,
    truth: String,
    /// Where the still scene estimate came from.
    static_source: String,
    /// Pearson correlation of the still scene estimate with the truth's.
    static_correlation: f64,
    /// `||v - t|| / ||t||` over the whole video (`null`: the truth is zero everywhere).
    rel_error: Option<f64>,
    /// The first channel's motion error (`null`: one frame, or a truth that does not
    /// move): `||s (v - mean_t v) - (t - mean_t t)|| / ||t - mean_t t||`, s the best
    /// scale of the video; a still scores 1.
    motion_error: Option<f64>,
    track: rollcam::analysis::track::TrackReport,
    /// Each analysed region's time course against the truth's in the same region.
    courses: Vec<rollcam::analysis::CourseAgainstTruth>,
}

/// The first channel of a (frames, rows, cols, channels) video, owned.
fn first_channel(v: &ndarray::Array4<f32>) -> ndarray::Array3<f32> {
    v.index_axis(ndarray::Axis(3), 0).to_owned()
}

/// `--truth`: track the object and compare the still scenes.
fn track_against_truth(
    a: &AnalyzeArgs,
    video_path: &std::path::Path,
    video: &ndarray::Array4<f32>,
    truth_path: &std::path::Path,
    out: &std::path::Path,
    (regions, unseen): (&[rollcam::analysis::report::RegionReport], &[[usize; 2]]),
) -> Result<()> {
    use rollcam::analysis::track;
    use rollcam::solve::trace::{compare, motion_error, ZERO_TRUTH};
    let truth = io::read_truth(truth_path)?;
    if truth.dim() != video.dim() {
        bail!("--truth {}: shape {:?} does not match the video's {:?} (frames, rows, cols, channels)", truth_path.display(), truth.dim(), video.dim());
    }
    positive("track-radius-px", a.track_radius_px)?;
    let (v, t) = (first_channel(video), first_channel(&truth));
    let static_file = video_path.parent().map(|d| d.join("static.npy")).filter(|p| p.is_file());
    let (static_est, static_source) = match &static_file {
        Some(p) => {
            let s = io::read_stack(p)?;
            let (_, r, c, _) = s.dim();
            if (r, c) != (v.dim().1, v.dim().2) {
                bail!("{}: a {r} x {c} image does not match the video's frames", p.display());
            }
            (s.index_axis(ndarray::Axis(0), 0).index_axis(ndarray::Axis(2), 0).to_owned(), p.display().to_string())
        }
        None => (track::static_estimate(v.view()), "per-pixel temporal median of the video".to_string()),
    };
    let static_truth = track::static_estimate(t.view());
    let report = track::track_errors(v.view(), t.view(), static_est.view(), static_truth.view(), a.track_radius_px);
    let frames = video.dim().0;
    let courses = rollcam::analysis::courses_against_truth(regions, video.view(), truth.view(), unseen);
    let summary = TrackSummary {
        video: video_path.display().to_string(),
        truth: truth_path.display().to_string(),
        static_correlation: track::correlation(static_est.view(), static_truth.view()),
        static_source,
        rel_error: compare(v.as_slice().expect("owned, standard layout"), t.as_slice().expect("owned, standard layout")).map(|e| e.rel_error),
        motion_error: motion_error(v.as_slice().expect("owned, standard layout"), t.as_slice().expect("owned, standard layout"), v.dim().0),
        track: report,
        courses,
    };
    let fmt = |v: Option<f64>| v.map_or("none".to_string(), |x| format!("{x:.2} px"));
    println!(
        "track of the {} object (frames {}..{}): median error {}, 90th percentile {} ({} counting the {} lost frames as misses); still scene correlation {:.3} ({}); relative error {}; motion error {} (a still scores 1)",
        match summary.track.contrast {
            track::Contrast::Brighter => "brighter",
            track::Contrast::Darker => "darker",
        },
        summary.track.first_frame,
        summary.track.end_frame,
        fmt(summary.track.median_px),
        fmt(summary.track.p90_px),
        summary.track.p90_px_with_lost.map_or("a lost frame".to_string(), |x| format!("{x:.2} px")),
        summary.track.frames_lost,
        summary.static_correlation,
        summary.static_source,
        summary.rel_error.map_or(format!("undefined ({ZERO_TRUTH})"), |e| format!("{e:.4}")),
        summary.motion_error.map_or("undefined (one frame, or the truth does not move)".to_string(), |e| format!("{e:.4}"))
    );
    let unseen_text = rollcam::solve::frames::runs_text(unseen, frames);
    for c in &summary.courses {
        let Some(r) = c.correlation else { continue };
        println!(
            "{}: time course against the truth's: correlation {r:.3} over the {frames} frames{}",
            c.name,
            c.correlation_seen.map_or(String::new(), |s| format!(
                ", {s:.3} over the {} the data see ({unseen_text} left out: summary.json support.sources.unseen_frames)",
                c.seen_frames
            ))
        );
    }
    let still: Vec<&str> = summary.courses.iter().filter(|c| c.truth_constant).map(|c| c.name.as_str()).collect();
    if !still.is_empty() {
        println!(
            "{}: the truth is the same in every frame there (a still part of the scene): no time course to compare (track.json courses: truth_constant)",
            if still.len() > 3 { format!("{} of the {} spots ({}, ...)", still.len(), summary.courses.len(), still[..3].join(", ")) } else { still.join(", ") }
        );
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    io::write_text_atomic(&out.join("track.json"), &serde_json::to_string_pretty(&summary).expect("track summary serialises"))?;
    Ok(())
}

fn positive(name: &str, v: f64) -> Result<f64> {
    if !(v.is_finite() && v > 0.0) {
        bail!("--{name} = {v}: expected a positive number");
    }
    Ok(v)
}

pub fn run(a: AnalyzeArgs) -> Result<()> {
    let input = resolve_input(a.rec_dir.as_deref(), a.video.as_deref(), a.config.as_deref(), a.out.as_deref())?;
    let rollcam::analysis::input::VideoInput { video: video_path, out, timing, config_grid, unseen_frames } = input;
    let inputs =
        [("the video", Some(video_path.as_path())), ("the capture description (--config)", a.config.as_deref()), ("the truth (--truth)", a.truth.as_deref())];
    crate::cli::common::claim_out(&out, &a.force, rollcam::analysis::report::ANALYSIS_FILES, &inputs)?;
    let video = io::read_stack(&video_path)?;
    if let Some(g) = &config_grid {
        let (_, rows, cols, _) = video.dim();
        g.check_video(&video_path, (rows, cols))?;
    }
    let geometry = match (a.distance_mm, a.pixel_pitch_um) {
        (Some(d), Some(p)) => Some(Geometry {
            distance_mm: positive("distance-mm", d)?,
            pixel_pitch_um: positive("pixel-pitch-um", p)?,
            object_distance_mm: a.object_distance_mm.map(|z| positive("object-distance-mm", z)).transpose()?,
        }),
        (None, None) => None,
        _ => bail!("angular resolution needs both --distance-mm and --pixel-pitch-um"),
    };
    let opts = AnalyzeOptions {
        regions: a.region.clone(),
        waveform_period_us: a.waveform_period_us,
        duty: a.duty,
        max_spots: a.max_spots,
        trim_frames: a.trim_frames,
        geometry,
        ..AnalyzeOptions::default()
    };
    let analysis = analyze_video(video.view(), &timing, &opts).with_context(|| format!("analysing {}", video_path.display()))?;
    if let Some(t) = &a.truth {
        track_against_truth(&a, &video_path, &video, t, &out, (&analysis.regions, &unseen_frames))?;
    }
    let analysis = write_analysis(&out, video.view(), analysis)?;
    let th = &analysis.theory;
    let [k, m, n, c] = analysis.video_shape;
    println!("video {}: {k} frames of {m} x {n} x {c}, frame time {:.1} us, exposure {:.1} us", video_path.display(), th.frame_time_us, th.exposure_us);
    println!(
        "theory: sampling {:.0} Hz, Nyquist {:.0} Hz, exposure first zero 1/T_e = {:.0} Hz, band limit {:.0} Hz; spectrum bin {:.1} Hz",
        th.sampling_rate_hz, th.nyquist_hz, th.exposure_first_zero_hz, th.band_limit_hz, analysis.bin_hz
    );
    for r in &analysis.regions {
        println!(
            "{}: Michelson contrast {:.2}{}, spectral peak {}",
            r.name,
            r.temporal_contrast,
            r.fundamental_contrast.map_or(String::new(), |f| format!(", fundamental contrast {f:.2}")),
            r.peak_frequency_hz.map_or("none".into(), |f| format!("{f:.1} Hz"))
        );
    }
    for d in &analysis.dips {
        println!(
            "spots {:?} and {:?}: {:.1} px apart, dip contrast {:.2} ({})",
            d.a,
            d.b,
            d.separation_px,
            d.contrast,
            if d.resolved { "resolved" } else { "not resolved" }
        );
    }
    if let Some(ang) = &analysis.angular {
        println!(
            "angular: {:.4} deg per pixel; smallest resolved separation {}",
            ang.degrees_per_pixel,
            ang.smallest_resolved_deg.map_or("none".into(), |d| format!(
                "{d:.3} deg{}",
                ang.smallest_resolved_mm.map_or(String::new(), |mm| format!(" ({mm:.2} mm at the object)"))
            ))
        );
    }
    if let Some(w) = &th.waveform {
        println!(
            "square wave {:.0} us ({:.1} Hz): contrast after the exposure {:.2}, fundamental transfer {:.2}",
            w.period_us, w.frequency_hz, w.contrast_after_exposure, w.fundamental_transfer
        );
        if let Some(g) = &w.global_shutter {
            println!(
                "global shutter with the same {} samples: {} frames at > {:.0} fps over {:.0} us, {} x {} pixels each ({:.1}x coarser)",
                g.samples, g.frames, g.min_frame_rate_fps, g.record_us, g.rows, g.cols, g.lateral_factor
            );
        }
    }
    if let Some(v) = &analysis.verdict {
        for note in &v.notes {
            println!("{note}");
        }
    }
    println!("wrote {} files to {}", analysis.files.len(), out.display());
    Ok(())
}
