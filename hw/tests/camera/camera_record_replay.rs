//! Recorder round trip and replay with fault injection.

use std::path::Path;
use std::time::{Duration, Instant};

use rollcam_hw::camera::replay::{Pace, ReplayCamera, ReplayFaults, ReplayOptions};
use rollcam_hw::camera::simulated::{FrameRenderer, RenderError, SimulatedCamera, SimulatedConfig};
use rollcam_hw::camera::{AppliedSettings, Camera, CameraError, CameraSettings, Frame, FrameStatus, SensorGeometry, Trigger};
use rollcam_hw::record::{CaptureReader, CaptureSession, Recorder, SyncInfo, TriggerLink};

/// Pseudo-random but deterministic pixels covering the full 16-bit range.
struct Noise;
impl FrameRenderer for Noise {
    fn geometry(&self) -> SensorGeometry {
        SensorGeometry { width: 24, height: 16, max_bit_depth: 16 }
    }
    fn render(&mut self, index: u64, s: &AppliedSettings) -> Result<Vec<u16>, RenderError> {
        let (w, h) = s.image_size();
        let mut x = 0x9e37_79b9_7f4a_7c15u64 ^ index;
        Ok((0..w * h)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x as u16
            })
            .collect())
    }
}

/// Record `n` frames from the simulated camera into `dir`, 5 ms apart.
fn record(dir: &Path, n: usize, trigger: Trigger) -> Vec<Frame> {
    let mut cam = SimulatedCamera::new(Noise, SimulatedConfig::default());
    let applied = cam.configure(&CameraSettings { trigger: Some(trigger.clone()), ..Default::default() }).unwrap();
    let mut session = CaptureSession::new(cam.info().clone());
    session.applied = Some(applied);
    session.sync = SyncInfo {
        led_phase_us: Some(12.5),
        line_time_us: Some(10.0),
        trigger_chain: vec![TriggerLink { source: "camera:Line1".into(), target: "led:in".into(), note: None }],
        led: Some(serde_json::json!({"pulse_width_us": 3.0})),
        notes: None,
    };
    let mut rec = Recorder::create(dir, session).unwrap();
    cam.start().unwrap();
    let mut frames = Vec::new();
    for _ in 0..n {
        if trigger == Trigger::Software {
            cam.software_trigger().unwrap();
        }
        let f = cam.next_frame(Duration::from_millis(100)).unwrap();
        rec.write_frame(&f).unwrap();
        frames.push(f);
        std::thread::sleep(Duration::from_millis(5));
    }
    rec.finish(None).unwrap();
    frames
}

#[test]
fn record_then_read_back_is_identical() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = record(tmp.path(), 4, Trigger::FreeRun);
    let reader = CaptureReader::open(tmp.path()).unwrap();
    assert_eq!(reader.len(), 4);
    for (i, f) in frames.iter().enumerate() {
        let back = reader.read_frame(i).unwrap();
        assert_eq!(&back, f, "frame {i} pixels and metadata survive the round trip");
    }
    let s = reader.session();
    assert_eq!(s.frames_recorded, 4);
    assert_eq!(s.sync.led_phase_us, Some(12.5));
    assert_eq!(s.sync.led.as_ref().unwrap()["pulse_width_us"], 3.0);
    assert_eq!(s.end.as_ref().unwrap().outcome, "completed");
    // Nothing temporary is left behind, and each frame is a TIFF + sidecar.
    let names: Vec<String> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(names.iter().all(|n| !n.ends_with(".tmp")), "{names:?}");
    assert!(names.contains(&"frame_000003.tiff".to_string()) && names.contains(&"frame_000003.json".to_string()));
    // The TIFF on disk is a standard 16-bit greyscale image.
    let (w, h, px) = rollcam_hw::record::decode_tiff16(&tmp.path().join("frame_000002.tiff")).unwrap();
    assert_eq!((w, h), (24, 16));
    assert_eq!(px, frames[2].pixels);
}

#[test]
fn recorder_refuses_to_overwrite_a_capture() {
    let tmp = tempfile::tempdir().unwrap();
    record(tmp.path(), 1, Trigger::FreeRun);
    let info = CaptureReader::open(tmp.path()).unwrap().session().camera.clone();
    let e = Recorder::create(tmp.path(), CaptureSession::new(info)).unwrap_err().to_string();
    assert!(e.contains("already holds a capture"), "{e}");
}

#[test]
fn incomplete_and_dropped_frames_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let mut frames = record(&tmp.path().join("src"), 3, Trigger::FreeRun);
    let info = CaptureReader::open(tmp.path().join("src")).unwrap().session().camera.clone();
    frames[1].pixels.truncate(100);
    frames[1].meta.valid_pixels = 100;
    frames[1].meta.status = FrameStatus::Incomplete;
    frames[2].pixels.clear();
    frames[2].meta.valid_pixels = 0;
    frames[2].meta.status = FrameStatus::Dropped;
    let dir = tmp.path().join("dst");
    let mut rec = Recorder::create(&dir, CaptureSession::new(info)).unwrap();
    for f in &frames {
        rec.write_frame(f).unwrap();
    }
    rec.finish(Some("camera unplugged".into())).unwrap();
    let reader = CaptureReader::open(&dir).unwrap();
    for (i, f) in frames.iter().enumerate() {
        assert_eq!(&reader.read_frame(i).unwrap(), f);
    }
    assert!(!dir.join("frame_000002.tiff").exists(), "dropped frames have no image");
    assert_eq!(reader.session().end.as_ref().unwrap().error.as_deref(), Some("camera unplugged"));
}

fn replay(dir: &Path, faults: ReplayFaults) -> ReplayCamera {
    let mut cam = ReplayCamera::open(dir, ReplayOptions { pace: Pace::AsFastAsConsumed, faults }).unwrap();
    cam.start().unwrap();
    cam
}

#[test]
fn replay_plays_back_every_frame_then_ends() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = record(tmp.path(), 5, Trigger::FreeRun);
    let mut cam = replay(tmp.path(), ReplayFaults::default());
    for f in &frames {
        let got = cam.next_frame(Duration::from_millis(50)).unwrap();
        assert_eq!(got.pixels, f.pixels);
        assert_eq!(got.meta.frame_id, f.meta.frame_id);
        assert_eq!(got.meta.settings, f.meta.settings);
    }
    let e = cam.next_frame(Duration::from_millis(50)).unwrap_err();
    assert!(matches!(e, CameraError::EndOfStream { frames: 5, .. }), "{e}");
}

#[test]
fn replay_drop_fault_surfaces_as_dropped_frame() {
    let tmp = tempfile::tempdir().unwrap();
    record(tmp.path(), 6, Trigger::FreeRun);
    let mut cam = replay(tmp.path(), ReplayFaults { drop: vec![3], ..Default::default() });
    let got: Vec<_> = (0..6).map(|_| cam.next_frame(Duration::from_millis(50)).unwrap()).collect();
    let statuses: Vec<_> = got.iter().map(|f| f.meta.status).collect();
    assert_eq!(statuses[3], FrameStatus::Dropped);
    assert!(statuses.iter().enumerate().all(|(i, s)| i == 3 || *s == FrameStatus::Complete), "{statuses:?}");
    assert!(got[3].pixels.is_empty());
    assert_eq!(got.iter().map(|f| f.meta.frame_id).collect::<Vec<_>>(), vec![0, 1, 2, 3, 4, 5]);
    assert_eq!(got.iter().map(|f| f.meta.sequence).collect::<Vec<_>>(), vec![0, 1, 2, 3, 4, 5]);
}

#[test]
fn replay_truncate_fault_gives_incomplete_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = record(tmp.path(), 6, Trigger::FreeRun);
    let mut cam = replay(tmp.path(), ReplayFaults { truncate: vec![5], ..Default::default() });
    for _ in 0..5 {
        assert_eq!(cam.next_frame(Duration::from_millis(50)).unwrap().meta.status, FrameStatus::Complete);
    }
    let f = cam.next_frame(Duration::from_millis(50)).unwrap();
    assert_eq!(f.meta.status, FrameStatus::Incomplete);
    assert_eq!(f.pixels.len(), 24 * 16 / 2);
    assert_eq!(f.meta.valid_pixels, f.pixels.len() as u64);
    assert_eq!(f.pixels[..], frames[5].pixels[..24 * 16 / 2]);
}

#[test]
fn replay_stall_fault_times_out_then_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    record(tmp.path(), 9, Trigger::FreeRun);
    let stall = Duration::from_millis(300);
    let mut cam = replay(tmp.path(), ReplayFaults { stall_at: Some((7, stall)), ..Default::default() });
    for _ in 0..7 {
        cam.next_frame(Duration::from_millis(50)).unwrap();
    }
    let t0 = Instant::now();
    let e = cam.next_frame(Duration::from_millis(50)).unwrap_err();
    assert!(matches!(e, CameraError::Timeout { timeout_ms: 50, .. }), "{e}");
    let f = cam.next_frame(Duration::from_secs(2)).unwrap();
    assert_eq!(f.meta.frame_id, 7);
    assert!(t0.elapsed() >= stall, "frame 7 arrived after {:?}", t0.elapsed());
    assert_eq!(cam.next_frame(Duration::from_millis(50)).unwrap().meta.frame_id, 8);
}

#[test]
fn replay_disconnect_fault_is_a_clear_persistent_error() {
    let tmp = tempfile::tempdir().unwrap();
    record(tmp.path(), 10, Trigger::FreeRun);
    let mut cam = replay(tmp.path(), ReplayFaults { disconnect_at: Some(9), ..Default::default() });
    for _ in 0..9 {
        cam.next_frame(Duration::from_millis(50)).unwrap();
    }
    for _ in 0..2 {
        let e = cam.next_frame(Duration::from_millis(50)).unwrap_err();
        assert!(matches!(e, CameraError::Disconnected { .. }), "{e}");
        assert!(e.to_string().contains("disconnected"), "{e}");
    }
}

#[test]
fn replay_at_recorded_pace_takes_the_recorded_time() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = record(tmp.path(), 5, Trigger::FreeRun);
    let span = Duration::from_nanos(frames[4].meta.host_timestamp_ns - frames[0].meta.host_timestamp_ns);
    let mut cam = ReplayCamera::open(tmp.path(), ReplayOptions { pace: Pace::Recorded, ..Default::default() }).unwrap();
    cam.start().unwrap();
    let t0 = Instant::now();
    for _ in 0..5 {
        cam.next_frame(Duration::from_secs(1)).unwrap();
    }
    assert!(t0.elapsed() >= span.mul_f64(0.9), "{:?} < recorded {:?}", t0.elapsed(), span);
}

#[test]
fn replay_settings_are_fixed_by_the_recording() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = record(tmp.path(), 2, Trigger::FreeRun);
    let mut cam = ReplayCamera::open(tmp.path(), ReplayOptions::default()).unwrap();
    let same = CameraSettings { exposure_us: Some(frames[0].meta.settings.exposure_us), ..Default::default() };
    assert_eq!(cam.configure(&same).unwrap(), frames[0].meta.settings);
    let e = cam.configure(&CameraSettings { exposure_us: Some(12345.0), ..Default::default() }).unwrap_err();
    assert!(e.to_string().contains("fixed by the recording"), "{e}");
}

#[test]
fn replay_of_software_triggered_capture_needs_triggers() {
    let tmp = tempfile::tempdir().unwrap();
    record(tmp.path(), 3, Trigger::Software);
    let mut cam = replay(tmp.path(), ReplayFaults::default());
    assert!(matches!(cam.next_frame(Duration::from_millis(20)), Err(CameraError::Timeout { .. })));
    cam.software_trigger().unwrap();
    assert_eq!(cam.next_frame(Duration::from_millis(20)).unwrap().meta.frame_id, 0);
    assert!(matches!(cam.next_frame(Duration::from_millis(20)), Err(CameraError::Timeout { .. })));
}

#[test]
fn replay_of_missing_folder_is_not_found() {
    let e = ReplayCamera::open("/nonexistent/capture", ReplayOptions::default()).err().unwrap();
    assert!(e.to_string().contains("/nonexistent/capture not found on replay"), "{e}");
}

/// A FIFO in place of capture.json, a frame sidecar or a frame TIFF blocked the reader
/// forever; an oversize sidecar was read into memory. Each is refused naming the file,
/// before it is opened.
#[test]
fn fifos_and_oversize_files_in_a_capture_folder_are_refused_without_blocking() {
    let fifo = |p: &Path| {
        std::fs::remove_file(p).unwrap();
        assert!(std::process::Command::new("mkfifo").arg(p).status().unwrap().success());
    };
    for (name, what) in [("capture.json", "read capture session"), ("frame_000001.json", "read frame metadata")] {
        let tmp = tempfile::tempdir().unwrap();
        record(tmp.path(), 2, Trigger::FreeRun);
        let path = tmp.path().join(name);
        fifo(&path);
        let e = CaptureReader::open(tmp.path()).unwrap_err().to_string();
        assert!(e.contains(name) && e.contains(what) && e.contains("FIFO") && e.contains("expected a regular file"), "{e}");
        // Past the bound on a text input (a sparse file: nothing is written).
        std::fs::remove_file(&path).unwrap();
        std::fs::File::create(&path).unwrap().set_len(rollcam_files::input::MAX_TEXT_BYTES + 1).unwrap();
        let e = CaptureReader::open(tmp.path()).unwrap_err().to_string();
        assert!(e.contains(name) && e.contains(&format!("{} bytes, more than the", rollcam_files::input::MAX_TEXT_BYTES + 1)), "{e}");
    }
    let tmp = tempfile::tempdir().unwrap();
    record(tmp.path(), 2, Trigger::FreeRun);
    let reader = CaptureReader::open(tmp.path()).unwrap();
    let tiff = tmp.path().join("frame_000001.tiff");
    fifo(&tiff);
    let e = reader.read_frame(1).unwrap_err().to_string();
    assert!(e.contains("frame_000001.tiff") && e.contains("FIFO"), "{e}");
    std::fs::remove_file(&tiff).unwrap();
    std::fs::File::create(&tiff).unwrap().set_len(rollcam_hw::record::MAX_FRAME_BYTES + 1).unwrap();
    let e = reader.read_frame(1).unwrap_err().to_string();
    assert!(e.contains("frame_000001.tiff") && e.contains("bytes, more than the"), "{e}");
}
