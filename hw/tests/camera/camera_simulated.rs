//! Simulated backend driven by a trivial renderer.

use std::time::Duration;

use rollcam_hw::camera::simulated::{FrameRenderer, RenderError, SimulatedCamera, SimulatedConfig};
use rollcam_hw::camera::{
    AppliedSettings, Binning, Camera, CameraError, CameraSettings, CameraShutter, FrameStatus, PixelFormat, Roi, SensorGeometry, Trigger,
};

/// Pixel value = frame index * 1000 + row; records the settings it was asked to render with.
struct RowRamp {
    seen: Vec<(u64, f64)>,
}

impl FrameRenderer for RowRamp {
    fn geometry(&self) -> SensorGeometry {
        SensorGeometry { width: 64, height: 48, max_bit_depth: 16 }
    }
    fn render(&mut self, index: u64, s: &AppliedSettings) -> Result<Vec<u16>, RenderError> {
        self.seen.push((index, s.exposure_us));
        let (w, h) = s.image_size();
        Ok((0..h).flat_map(|row| std::iter::repeat((index * 1000 + row as u64) as u16).take(w as usize)).collect())
    }
}

fn camera() -> SimulatedCamera<RowRamp> {
    SimulatedCamera::new(RowRamp { seen: Vec::new() }, SimulatedConfig::default())
}

#[test]
fn renders_with_applied_settings_and_binning() {
    let mut cam = camera();
    let applied = cam
        .configure(&CameraSettings {
            exposure_us: Some(250.0),
            line_time_us: Some(7.5),
            shutter: Some(CameraShutter::Rolling),
            roi: Some(Roi { x: 8, y: 4, width: 32, height: 20 }),
            binning: Some(Binning { horizontal: 2, vertical: 2 }),
            pixel_format: Some(PixelFormat::Mono16),
            ..Default::default()
        })
        .unwrap();
    assert_eq!(applied.image_size(), (16, 10));
    assert_eq!(applied.line_time_us, Some(7.5));
    cam.start().unwrap();
    for i in 0..3u64 {
        let f = cam.next_frame(Duration::from_millis(100)).unwrap();
        assert_eq!((f.meta.width, f.meta.height), (16, 10));
        assert_eq!(f.pixels.len(), 160);
        assert_eq!(f.meta.frame_id, i);
        assert_eq!(f.meta.status, FrameStatus::Complete);
        assert_eq!(f.pixels[16 * 3], (i * 1000 + 3) as u16, "row 3 of frame {i}");
        assert_eq!(f.meta.settings.exposure_us, 250.0);
    }
    cam.stop().unwrap();
    assert_eq!(cam.renderer().seen, vec![(0, 250.0), (1, 250.0), (2, 250.0)]);
}

#[test]
fn mono8_clamps_to_bit_depth() {
    let mut cam = camera();
    cam.configure(&CameraSettings { pixel_format: Some(PixelFormat::Mono8), ..Default::default() }).unwrap();
    cam.start().unwrap();
    cam.next_frame(Duration::from_millis(10)).unwrap();
    let f = cam.next_frame(Duration::from_millis(10)).unwrap();
    assert_eq!(f.meta.bit_depth, 8);
    assert_eq!(f.pixels[0], 255, "1000 clamps to 255 in 8 bits");
}

#[test]
fn out_of_range_and_unsupported_settings_are_refused() {
    let mut cam = camera();
    let e = cam.configure(&CameraSettings { exposure_us: Some(0.5), ..Default::default() }).unwrap_err();
    assert!(matches!(e, CameraError::OutOfRange { .. }));
    assert_eq!(e.to_string(), "camera sim:sim0: ExposureTime 0.5 us out of range [1, 1000000] us");
    let e = cam.configure(&CameraSettings { shutter: Some(CameraShutter::Dual), ..Default::default() }).unwrap_err();
    assert!(e.to_string().contains("shutter"), "{e}");
    let e = cam.configure(&CameraSettings { roi: Some(Roi { x: 40, y: 0, width: 32, height: 8 }), ..Default::default() }).unwrap_err();
    assert!(e.to_string().contains("64x48"), "{e}");
    // Nothing was applied by the refused requests.
    assert_eq!(cam.applied_settings().unwrap().exposure_us, SimulatedConfig::default().exposure_us);
}

#[test]
fn software_trigger_yields_exactly_the_triggered_frames() {
    let mut cam = camera();
    cam.configure(&CameraSettings { trigger: Some(Trigger::Software), ..Default::default() }).unwrap();
    cam.start().unwrap();
    assert!(matches!(cam.next_frame(Duration::from_millis(20)), Err(CameraError::Timeout { .. })));
    cam.software_trigger().unwrap();
    cam.software_trigger().unwrap();
    assert_eq!(cam.next_frame(Duration::from_millis(20)).unwrap().meta.frame_id, 0);
    assert_eq!(cam.next_frame(Duration::from_millis(20)).unwrap().meta.frame_id, 1);
    assert!(matches!(cam.next_frame(Duration::from_millis(20)), Err(CameraError::Timeout { .. })));
}

#[test]
fn real_time_free_run_paces_frames() {
    let mut cam = SimulatedCamera::new(RowRamp { seen: Vec::new() }, SimulatedConfig { real_time: true, ..Default::default() });
    cam.configure(&CameraSettings { frame_rate_hz: Some(50.0), ..Default::default() }).unwrap();
    cam.start().unwrap();
    let t0 = std::time::Instant::now();
    for _ in 0..4 {
        cam.next_frame(Duration::from_secs(1)).unwrap();
    }
    // frames 0..3 are due at 0, 20, 40, 60 ms
    assert!(t0.elapsed() >= Duration::from_millis(55), "{:?}", t0.elapsed());
    // A timeout shorter than the frame period gives a timeout, not a frame.
    assert!(matches!(cam.next_frame(Duration::from_millis(1)), Err(CameraError::Timeout { .. })));
}

#[test]
fn renderer_returning_wrong_size_is_an_error() {
    struct Bad;
    impl FrameRenderer for Bad {
        fn geometry(&self) -> SensorGeometry {
            SensorGeometry { width: 4, height: 4, max_bit_depth: 16 }
        }
        fn render(&mut self, _: u64, _: &AppliedSettings) -> Result<Vec<u16>, RenderError> {
            Ok(vec![0; 3])
        }
    }
    let mut cam = SimulatedCamera::new(Bad, SimulatedConfig::default());
    cam.start().unwrap();
    let e = cam.next_frame(Duration::from_millis(10)).unwrap_err().to_string();
    assert!(e.contains("3 samples") && e.contains("4x4"), "{e}");
}
