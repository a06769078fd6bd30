//! `rollcam calibrate`: a bench calibration folder (`calibration.toml`, `dark.tiff`,
//! `defects.tiff`, `psf.tiff`, `background.tiff`, and a one-page `report.png`) from dark
//! frames, point-source shots and background frames.

use anyhow::{bail, Context, Result};
use clap::Args;
use ndarray::{Array3, Axis};
use rollcam::analysis::calibrate::{calibrate, report_figure, CalibrateError, CalibrationInput, SaturationOrigin, BACKGROUND_FRAMES, DARK_FRAMES, PSF_SHOTS};
use rollcam::io::calibration::{write_calibration, BACKGROUND_FILE, DARK_FILE, DEFECTS_FILE, PSF_FILE, RECORD_FILE};
use rollcam::io::{self, Display};
use std::path::{Path, PathBuf};

/// The figure written beside the calibration.
pub const REPORT_FIGURE: &str = "report.png";

#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// Dark frames (lens cap on, the captures' exposure): image files, folders of
    /// images (read in natural order of names), multi-page TIFFs or 3D/4D NPY stacks;
    /// every item adds its frames.
    #[arg(long, num_args = 1.., value_name = "PATH")]
    pub dark: Vec<PathBuf>,
    /// Point-source shots (the PSF), as --dark.
    #[arg(long = "psf-shots", num_args = 1.., value_name = "PATH")]
    pub psf_shots: Vec<PathBuf>,
    /// Background frames (the static scene without the moving object), as --dark.
    #[arg(long, num_args = 1.., value_name = "PATH")]
    pub background: Vec<PathBuf>,
    /// Raw value at which pixels clip, in counts (default: a pile of pixels at the
    /// largest value of the PSF or background shots, else unknown).
    #[arg(long, value_name = "COUNTS")]
    pub saturation_level: Option<f64>,
    /// Shift the PSF by whole pixels so its centroid lands on the sensor centre.
    #[arg(long)]
    pub register: bool,
    /// Output folder: created; refused when it exists and is not empty (see --force).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::cli::common::ForceFlag,
}

/// The frames of one flag, and which item each came from.
struct Stack {
    frames: Vec<Array3<f32>>,
    /// Each item given, and how many frames it held.
    items: Vec<(PathBuf, usize)>,
}

impl Stack {
    /// The item frame `index` came from, and its index there.
    fn source(&self, index: usize) -> Option<(&Path, usize)> {
        let mut start = 0;
        for (p, n) in &self.items {
            if index < start + n {
                return Some((p, index - start));
            }
            start += n;
        }
        None
    }

    /// The items for the record: absolute paths where they can be made.
    fn files(&self) -> Vec<String> {
        self.items.iter().map(|(p, _)| std::path::absolute(p).unwrap_or_else(|_| p.clone()).display().to_string()).collect()
    }
}

/// Refuses an `--out` that exists and is not an empty folder.
fn check_out(out: &Path) -> Result<()> {
    if !out.exists() {
        return Ok(());
    }
    if !out.is_dir() {
        bail!("--out {}: exists and is not a folder; give a new or empty folder", out.display());
    }
    let mut entries = std::fs::read_dir(out).with_context(|| format!("--out {}: cannot list the folder", out.display()))?;
    if entries.next().is_some() {
        bail!("--out {}: the folder exists and is not empty; give a new or empty folder (calibrate never replaces files)", out.display());
    }
    Ok(())
}

fn read_items(flag: &str, paths: &[PathBuf]) -> Result<Stack> {
    let mut stack = Stack { frames: Vec::new(), items: Vec::new() };
    for p in paths {
        let video = io::read_stack(p).with_context(|| format!("--{flag}: reading {}", p.display()))?;
        let n = video.dim().0;
        stack.frames.extend(video.axis_iter(Axis(0)).map(|f| f.to_owned()));
        stack.items.push((p.clone(), n));
    }
    Ok(stack)
}

/// The library's error, with the file a frame came from when it names a frame.
fn with_source(e: CalibrateError, stacks: &[(&str, &Stack)]) -> anyhow::Error {
    let at = e.frame_index().zip(e.stack()).and_then(|(i, name)| stacks.iter().find(|(n, _)| *n == name).and_then(|(_, s)| s.source(i)));
    match at {
        Some((path, j)) => anyhow::Error::new(e).context(format!("frame {j} of {}", path.display())),
        None => anyhow::Error::new(e),
    }
}

fn kind_counts(r: &rollcam::model::sensor::DefectRecord) -> String {
    format!("{} hot, {} stuck, {} noisy, {} dead: {} in all ({:.4}% of the pixels)", r.hot, r.stuck, r.noisy, r.dead, r.total, 100.0 * r.fraction)
}

pub fn run(a: CalibrateArgs) -> Result<()> {
    // Validate everything before reading a frame.
    if a.dark.is_empty() && a.psf_shots.is_empty() {
        bail!("nothing to calibrate: give --dark and/or --psf-shots (--background alone is not a calibration)");
    }
    if let Some(s) = a.saturation_level {
        if !(s.is_finite() && s > 0.0) {
            bail!("--saturation-level = {s}: expected a positive number of counts");
        }
    }
    for (flag, paths) in [("dark", &a.dark), ("psf-shots", &a.psf_shots), ("background", &a.background)] {
        for p in paths.iter() {
            if !p.exists() {
                bail!("--{flag} {}: no such file or folder", p.display());
            }
        }
    }
    let inputs: Vec<(&str, Option<&Path>)> =
        [("a dark frame (--dark)", &a.dark), ("a PSF shot (--psf-shots)", &a.psf_shots), ("a background frame (--background)", &a.background)]
            .into_iter()
            .flat_map(|(role, paths)| paths.iter().map(move |p| (role, Some(p.as_path()))))
            .collect();
    let writes = [RECORD_FILE, DARK_FILE, DEFECTS_FILE, PSF_FILE, BACKGROUND_FILE, REPORT_FIGURE];
    crate::cli::common::claim_out(&a.out, &a.force, &writes, &inputs)?;

    let dark = read_items("dark", &a.dark)?;
    let psf = read_items("psf-shots", &a.psf_shots)?;
    let background = read_items("background", &a.background)?;
    let stacks = [(DARK_FRAMES, &dark), (PSF_SHOTS, &psf), (BACKGROUND_FRAMES, &background)];
    let input =
        CalibrationInput { dark: &dark.frames, psf: &psf.frames, background: &background.frames, saturation_level: a.saturation_level, register: a.register };
    let outcome = calibrate(&input).map_err(|e| with_source(e, &stacks))?;
    let mut cal = outcome.calibration;
    let now_ns = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(0);
    cal.record.created_utc = io::utc::utc_string(now_ns);
    if let Some(d) = cal.record.dark.as_mut() {
        d.files = dark.files();
    }
    if let Some(p) = cal.record.psf.as_mut() {
        p.files = psf.files();
    }
    if let Some(b) = cal.record.background.as_mut() {
        b.files = background.files();
    }

    // Write: the folder is checked again right before (it may have been filled meanwhile).
    if !a.force.force {
        check_out(&a.out)?;
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("--out {}: cannot create the folder", a.out.display()))?;
    write_calibration(&a.out, &cal)?;
    let figure = report_figure(&cal);
    io::write_png(a.out.join(REPORT_FIGURE), figure.view(), &Display::linear(0.0, 255.0))?;

    // Report.
    let r = &cal.record;
    println!("sensor {} x {} with {} channel{}", r.rows, r.cols, r.channels, if r.channels == 1 { "" } else { "s" });
    if let Some(d) = &r.dark {
        println!(
            "dark: {} frames from {} item(s); median level {:.2} counts, read noise {:.3} counts rms, fixed pattern {:.3} counts rms",
            d.frames,
            dark.items.len(),
            d.median_level,
            d.read_noise,
            d.fixed_pattern_rms
        );
    }
    if let Some(m) = &r.defects {
        println!("defects: {}", kind_counts(m));
    }
    match (&r.saturation_level, &outcome.saturation_origin) {
        (Some(s), Some(SaturationOrigin::Given)) => println!("saturation level {s} counts (--saturation-level)"),
        (Some(s), Some(SaturationOrigin::Detected(f))) => {
            let at = stacks.iter().find(|(n, _)| *n == f.stack).and_then(|(_, st)| st.source(f.frame));
            let place = at.map_or(format!("{} frame {}", f.stack, f.frame), |(p, j)| format!("frame {j} of {}", p.display()));
            println!("saturation level {s} counts (detected: a pile of pixels at the largest value in {place})");
        }
        _ => println!("saturation level: unknown (no --saturation-level, and no pile of clipped pixels in the shots)"),
    }
    if let Some(p) = &r.psf {
        println!(
            "PSF: {} shots; centre (row {:.2}, col {:.2}){}; energy {:.4e} counts; edge fraction {:.4}; peak SNR {:.1}; {} pixels repaired ({} clipped, {} hot and {} dead found in the shots)",
            p.frames,
            p.centre_row,
            p.centre_col,
            if p.shift != [0, 0] { format!(", shifted by {:?} px to the sensor centre", p.shift) } else { String::new() },
            p.energy_counts,
            p.edge_fraction,
            p.peak_snr,
            p.repaired,
            outcome.psf_clipped_pixels,
            outcome.psf_outliers_hot,
            outcome.psf_outliers_dead
        );
    }
    if let Some(b) = &r.background {
        println!("background: {} frames; mean {:.3} counts above the dark", b.frames, b.mean_above_dark);
    }
    for note in &outcome.notes {
        println!("note: {note}");
    }
    let mut files = vec![RECORD_FILE];
    for (present, name) in
        [(cal.dark.is_some(), DARK_FILE), (cal.defects.is_some(), DEFECTS_FILE), (cal.psf.is_some(), PSF_FILE), (cal.background.is_some(), BACKGROUND_FILE)]
    {
        if present {
            files.push(name);
        }
    }
    files.push(REPORT_FIGURE);
    println!("wrote {} to {}", files.join(", "), a.out.display());
    Ok(())
}
