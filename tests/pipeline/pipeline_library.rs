//! The pipeline as a library: any `FrameReconstructor` plugs in (here one that
//! records which frames it saw and fails one), faults from the replay camera, and the
//! timing checks against what a camera applied ([`rollcam::lab::hardware::check_timing`]).

use rollcam::lab::hardware::check_timing;
use rollcam::lab::pipeline::session::{SessionConfig, SessionFile, State};
use rollcam::lab::pipeline::worker::{FrameJob, FrameReconstructor, FrameVideo, ReconstructFailure};
use rollcam::lab::pipeline::{self, Options, Policy};
use rollcam::solve::problem::ValidSettings;
use rollcam_hw::camera::replay::{ReplayCamera, ReplayFaults, ReplayOptions};
use rollcam_hw::camera::Camera;
use rollcam_hw::record::CaptureSession;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

fn fixture() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/captures/led-505hz")
}

/// Writes the raw's mean as a one-pixel "video"; fails on one frame.
struct MeanOfRaw {
    seen: Mutex<Vec<u64>>,
    fail_on: u64,
}

impl FrameReconstructor for MeanOfRaw {
    fn reconstruct(&self, job: &FrameJob, _stop: &AtomicBool) -> Result<FrameVideo, ReconstructFailure> {
        self.seen.lock().unwrap().push(job.sequence);
        if job.sequence == self.fail_on {
            return Err(anyhow::anyhow!("cannot reconstruct frame {}", job.sequence).into());
        }
        let raw = rollcam::io::read_image(&job.raw).map_err(anyhow::Error::from)?;
        let mean = raw.iter().map(|&v| v as f64).sum::<f64>() / raw.len() as f64;
        std::fs::create_dir_all(&job.out).unwrap();
        let video = ndarray::Array4::from_elem((1, 1, 1, 1), mean as f32);
        rollcam::io::write_npy(job.out.join("video.npy"), video.view()).map_err(anyhow::Error::from)?;
        Ok(FrameVideo {
            video: job.out.join("video.npy"),
            solve_s: 0.0,
            psnr_db: None,
            converged: None,
            preview: ndarray::Array3::from_elem((4, 4, 1), mean as f32),
            sequence_frames: None,
            sequence: None,
        })
    }
}

#[test]
fn any_reconstructor_plugs_in_and_faults_are_accounted_for() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("s");
    let cfg = rollcam::model::capture::CaptureConfig::load(&fixture().join("capture.toml")).unwrap();
    pipeline::create_folder(&dir, &cfg, pipeline::PsfInput::File(&fixture().join("psf.tiff"))).unwrap();
    let faults = ReplayFaults { drop: vec![1], ..Default::default() };
    let cam = ReplayCamera::open(fixture(), ReplayOptions { faults, ..Default::default() }).unwrap();
    let raw = CaptureSession::new(cam.info().clone());
    let config = SessionConfig {
        capture: cfg,
        psf: "psf.tiff".into(),
        psf_source: "fixture".into(),
        policy: "catch-up".into(),
        queue: 1,
        workers: 2,
        frames_requested: None,
        min_free_mb: 0,
        solver: ValidSettings::default(),
        truth_dir: None,
        outputs: Default::default(),
        consecutive: None,
        background: None,
        psf_dark_subtracted: false,
    };
    let session = SessionFile::new(cam.info().spec(), config);
    let rec = Arc::new(MeanOfRaw { seen: Mutex::new(Vec::new()), fail_on: 2 });
    let opts = Options { queue: 1, workers: 2, policy: Policy::CatchUp, min_free_mb: 0, ..Options::new(&dir) };
    let s = pipeline::run(Box::new(cam), raw, session, rec.clone(), opts, Arc::new(AtomicBool::new(false))).unwrap();
    let mut seen = rec.seen.lock().unwrap().clone();
    seen.sort_unstable();
    assert_eq!(seen, vec![0, 2]);
    assert_eq!(s.state, State::Finished);
    let c = &s.counters;
    assert_eq!((c.captured, c.recorded, c.reconstructed, c.failed, c.dropped, c.queued), (2, 2, 1, 1, 1, 0));
    assert_eq!(s.frames[1].error.as_deref(), Some("cannot reconstruct frame 2"));
    // The one-pixel video holds the raw's mean.
    let v = rollcam::io::read_npy(dir.join("rec/frame_000000/video.npy")).unwrap();
    let raw = rollcam::io::read_image(fixture().join("frame_000000.tiff")).unwrap();
    let mean = raw.iter().map(|&v| v as f64).sum::<f64>() / raw.len() as f64;
    assert!((v[[0, 0, 0, 0]] as f64 - mean).abs() < 1e-3 * mean);
    // What was written is what was returned.
    assert_eq!(SessionFile::load(&dir).unwrap(), s);
}

#[test]
fn timing_contradictions_name_the_field() {
    let cfg = rollcam::model::capture::CaptureConfig::load(&fixture().join("capture.toml")).unwrap();
    let mut cam = ReplayCamera::open(fixture(), ReplayOptions::default()).unwrap();
    let applied = cam.applied_settings().unwrap();
    check_timing(&cfg, &applied, "bench.toml").unwrap();
    let mut c = cfg.clone();
    c.exposure_us = 700.0;
    let e = check_timing(&c, &applied, "bench.toml").unwrap_err().to_string();
    assert!(e.contains("bench.toml: exposure_us = 700") && e.contains("660"), "{e}");
    let mut c = cfg.clone();
    c.line_time_us = 219.0;
    let e = check_timing(&c, &applied, "bench.toml").unwrap_err().to_string();
    assert!(e.contains("line_time_us = 219") && e.contains("220"), "{e}");
    let mut c = cfg.clone();
    c.shutter = rollcam::model::shutter::ShutterMode::Rolling;
    let e = check_timing(&c, &applied, "bench.toml").unwrap_err().to_string();
    assert!(e.contains("shutter = rolling") && e.contains("dual"), "{e}");
    let mut c = cfg;
    c.cols = 60;
    let e = check_timing(&c, &applied, "bench.toml").unwrap_err().to_string();
    assert!(e.contains("cols = 60") && e.contains("48 x 64"), "{e}");
}
