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
    let timing = match (config, &summary) {
        (Some(c), _) => {
            let cfg = CaptureConfig::load(c)?;
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
    Ok(VideoInput { video: video_path, out, timing })
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
}
