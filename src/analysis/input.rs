//! What `rollcam analyze` reads: the video of a reconstruction folder (`video.npy` or
//! `video.tiff`) or a video file, where the analysis goes, and the timing of the video
//! (a capture.toml, the folder's `summary.json`, or both: the summary's frame time
//! wins).

use super::report::VideoTiming;
use crate::model::capture::CaptureConfig;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// A video to analyse, where its analysis goes, and its timing.
#[derive(Clone, Debug)]
pub struct VideoInput {
    pub video: PathBuf,
    pub out: PathBuf,
    pub timing: VideoTiming,
    /// The capture description given (`--config`): its name and the video grids it
    /// allows ([`ConfigGrid`]).
    pub config_grid: Option<ConfigGrid>,
    /// Runs `[first, end)` of the frames in which the folder's `summary.json` says a
    /// source's brightness is not in the data (its first channel's kept sources,
    /// `support.sources.unseen_frames`); empty for a video file or none reported.
    pub unseen_frames: Vec<[usize; 2]>,
}

/// The unseen frames a reconstruction's `summary.json` reports
/// ([`VideoInput::unseen_frames`]); empty when it reports none or cannot be read (the
/// timing's reading names a bad summary).
pub fn unseen_frames(summary: &Path) -> Vec<[usize; 2]> {
    let Some(v) = crate::io::input::read_text(summary).ok().and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok()) else {
        return Vec::new();
    };
    let sources = v.pointer("/channels/0/support/sources").filter(|s| s.get("kept").and_then(|k| k.as_bool()) == Some(true));
    sources.and_then(|s| s.get("unseen_frames")).and_then(|u| serde_json::from_value::<Vec<[usize; 2]>>(u.clone()).ok()).unwrap_or_default()
}

/// The video grids a capture description allows: the sensor's after downsampling
/// (`CaptureConfig::grid`, the `sensor` field of view) and the full field of view's,
/// `(2M - 1) x (2N - 1)` (the convolution's `Conv2d::full`), whichever one the video was
/// reconstructed on (`--fov` may override the file's).
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigGrid {
    pub name: String,
    pub sensor: (usize, usize),
}

impl ConfigGrid {
    pub fn of(cfg: &CaptureConfig, name: &str) -> ConfigGrid {
        ConfigGrid { name: name.to_string(), sensor: cfg.grid() }
    }

    /// The full field of view's grid of this sensor grid.
    pub fn full(&self) -> (usize, usize) {
        let (m, n) = self.sensor;
        ((2 * m).saturating_sub(1), (2 * n).saturating_sub(1))
    }

    /// Refuse a video of `rows x cols` pixels per frame this description cannot
    /// describe: its timing (line time, rows) would be read for another capture.
    pub fn check_video(&self, video: &Path, (rows, cols): (usize, usize)) -> Result<()> {
        if (rows, cols) == self.sensor || (rows, cols) == self.full() {
            return Ok(());
        }
        let ((m, n), (fm, fn_)) = (self.sensor, self.full());
        bail!(
            "{}: describes a sensor grid of {m} x {n} (rows / downsample x cols / downsample), so a video of {m} x {n} (fov sensor) or {fm} x {fn_} (fov full); {} has frames of {rows} x {cols}: expected the capture description of this video",
            self.name,
            video.display()
        )
    }
}

/// The video, output folder and timing from either a reconstruction folder `rec_dir`
/// or a video file `video` (not both), with an optional capture.toml `config` (needed
/// for a video file) and output folder `out` (default: `REC_DIR/analysis`, or
/// `STEM-analysis` beside the video).
pub fn resolve_input(rec_dir: Option<&Path>, video: Option<&Path>, config: Option<&Path>, out: Option<&Path>) -> Result<VideoInput> {
    let (video_path, out, summary) = match (rec_dir, video) {
        (Some(_), Some(_)) => bail!("give either a reconstruction folder or --video, not both"),
        (None, None) => bail!("nothing to analyse: give a reconstruction folder or --video FILE --config capture.toml"),
        (Some(dir), None) => {
            if !dir.is_dir() {
                bail!("{}: not a folder: expected a reconstruction folder with video.npy or video.tiff and summary.json", dir.display());
            }
            let v = [dir.join("video.npy"), dir.join("video.tiff")]
                .into_iter()
                .find(|p| p.exists())
                .with_context(|| format!("{}: no video.npy or video.tiff in the folder", dir.display()))?;
            (v, out.map(Path::to_path_buf).unwrap_or_else(|| dir.join("analysis")), Some(dir.join("summary.json")))
        }
        (None, Some(v)) => {
            let stem = v.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "video".into());
            let out = out.map(Path::to_path_buf).unwrap_or_else(|| v.with_file_name(format!("{stem}-analysis")));
            (v.to_path_buf(), out, None)
        }
    };
    let mut config_grid = None;
    let timing = match (config, &summary) {
        (Some(c), _) => {
            let cfg = CaptureConfig::load(c)?;
            config_grid = Some(ConfigGrid::of(&cfg, &c.display().to_string()));
            // The frame time of a folder's summary wins over the config's (same capture).
            let ft = summary.as_ref().filter(|s| s.exists()).and_then(|s| VideoTiming::from_summary(s).ok()).map(|t| t.frame_time_us);
            VideoTiming::from_config(&cfg, ft, &c.display().to_string())?
        }
        (None, Some(s)) => {
            if !s.exists() {
                bail!("{}: missing: the video has no timing; expected summary.json from `rollcam reconstruct`, or give --config capture.toml", s.display());
            }
            VideoTiming::from_summary(s)?
        }
        (None, None) => bail!("{}: a video without timing: give --config capture.toml (frame time and exposure)", video_path.display()),
    };
    let unseen_frames = summary.as_deref().filter(|s| s.exists()).map(unseen_frames).unwrap_or_default();
    Ok(VideoInput { video: video_path, out, timing, config_grid, unseen_frames })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_video_file_needs_a_config_and_one_source() {
        let e = resolve_input(None, Some(Path::new("/nowhere/v.npy")), None, None).unwrap_err().to_string();
        assert_eq!(e, "/nowhere/v.npy: a video without timing: give --config capture.toml (frame time and exposure)");
        let e = resolve_input(Some(Path::new("/a")), Some(Path::new("/b")), None, None).unwrap_err().to_string();
        assert!(e.contains("not both"), "{e}");
        assert!(resolve_input(None, None, None, None).unwrap_err().to_string().starts_with("nothing to analyse"));
    }

    #[test]
    fn a_description_fits_its_sensor_or_full_grid_and_nothing_else() {
        let g = ConfigGrid { name: "c.toml".into(), sensor: (48, 64) };
        let v = Path::new("v.npy");
        assert!(g.check_video(v, (48, 64)).is_ok());
        assert!(g.check_video(v, (95, 127)).is_ok());
        // 47 rows described, 48 in the video (and the other way round).
        let e = g.check_video(v, (47, 64)).unwrap_err().to_string();
        assert!(e.contains("c.toml") && e.contains("48 x 64") && e.contains("v.npy has frames of 47 x 64"), "{e}");
        assert!(ConfigGrid { name: "c.toml".into(), sensor: (47, 64) }.check_video(v, (48, 64)).is_err());
    }
}
