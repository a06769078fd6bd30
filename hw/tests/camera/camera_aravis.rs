//! GenICam backend against aravis' fake cameras, using rollcam's GenICam XML.
#![cfg(feature = "aravis")]

use std::time::Duration;

use rollcam_hw::camera::aravis::arv::prelude::*;
use rollcam_hw::camera::aravis::{start_gv_fake_camera, AravisCamera, AravisOptions};
use rollcam_hw::camera::{Binning, Camera, CameraError, CameraSettings, CameraShutter, Edge, FrameStatus, PixelFormat, Roi, Trigger};

/// aravis' fake devices and device list are process-global; run these tests one at a time.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn open_fake() -> AravisCamera {
    AravisCamera::open("Fake_1", &AravisOptions::default()).expect("open Fake_1")
}

#[test]
fn fake_camera_applies_settings_and_reads_them_back() {
    let _g = serial();
    let mut cam = open_fake();
    assert_eq!(cam.profile().name, "aravis-fake");
    let geo = cam.geometry().unwrap();
    assert!(geo.width >= 640 && geo.height >= 480, "{geo:?}");
    assert_eq!(geo.max_bit_depth, 16);
    let caps = cam.capabilities().unwrap();
    assert_eq!(caps.shutter_modes, vec![CameraShutter::Global, CameraShutter::Rolling, CameraShutter::Dual]);
    assert_eq!(caps.exposure_range_us, Some((10.0, 10_000_000.0)));
    assert_eq!(caps.line_time_range_us, Some((1.0, 1000.0)));
    assert!(caps.pixel_formats.contains(&PixelFormat::Mono16));

    for (shutter, line_time_us, exposure_us) in [(CameraShutter::Rolling, 12.5, 2500.0), (CameraShutter::Dual, 3.25, 800.0)] {
        let applied = cam
            .configure(&CameraSettings {
                exposure_us: Some(exposure_us),
                line_time_us: Some(line_time_us),
                frame_rate_hz: Some(50.0),
                shutter: Some(shutter),
                roi: Some(Roi { x: 16, y: 8, width: 320, height: 240 }),
                binning: Some(Binning { horizontal: 1, vertical: 1 }),
                pixel_format: Some(PixelFormat::Mono8),
                trigger: Some(Trigger::FreeRun),
                exposure_output_line: Some("Line1".into()),
            })
            .unwrap();
        assert_eq!(applied.exposure_us, exposure_us);
        assert!((applied.line_time_us.unwrap() - line_time_us).abs() < 1e-3, "{applied:?}");
        assert!((applied.frame_rate_hz.unwrap() - 50.0).abs() < 1e-6);
        assert_eq!(applied.shutter, Some(shutter));
        assert_eq!(applied.roi, Roi { x: 16, y: 8, width: 320, height: 240 });
        assert_eq!(applied.pixel_format, PixelFormat::Mono8);
        assert_eq!(applied.trigger, Trigger::FreeRun);
        assert_eq!(applied.exposure_output_line.as_deref(), Some("Line1"));
        // Read back independently of configure().
        assert_eq!(cam.applied_settings().unwrap(), applied);
        // ... and straight from the GenICam nodes.
        assert_eq!(cam.raw().string("SensorShutterMode").unwrap().as_str(), if shutter == CameraShutter::Rolling { "Rolling" } else { "Dual" });
        assert_eq!(cam.raw().integer("Width").unwrap(), 320);
    }
    cam.configure(&CameraSettings {
        trigger: Some(Trigger::Hardware { line: "Line0".into(), edge: Edge::Falling }),
        binning: Some(Binning { horizontal: 2, vertical: 2 }),
        ..Default::default()
    })
    .unwrap();
    let applied = cam.applied_settings().unwrap();
    assert_eq!(applied.trigger, Trigger::Hardware { line: "Line0".into(), edge: Edge::Falling });
    assert_eq!(applied.binning, Binning { horizontal: 2, vertical: 2 });
    assert_eq!(cam.raw().string("TriggerActivation").unwrap().as_str(), "FallingEdge");
}

#[test]
fn fake_camera_streams_frames_with_increasing_ids_and_timestamps() {
    let _g = serial();
    let mut cam = open_fake();
    let applied = cam
        .configure(&CameraSettings {
            // The fake camera scales its ramp by 1 + log10(exposure / 10 ms): 10 ms gives the raw ramp.
            exposure_us: Some(10_000.0),
            frame_rate_hz: Some(50.0),
            roi: Some(Roi { x: 0, y: 0, width: 128, height: 64 }),
            binning: Some(Binning { horizontal: 1, vertical: 1 }),
            pixel_format: Some(PixelFormat::Mono8),
            shutter: Some(CameraShutter::Rolling),
            line_time_us: Some(20.0),
            trigger: Some(Trigger::FreeRun),
            ..Default::default()
        })
        .unwrap();
    cam.start().unwrap();
    let frames: Vec<_> = (0..5).map(|_| cam.next_frame(Duration::from_secs(2)).unwrap()).collect();
    cam.stop().unwrap();
    for w in frames.windows(2) {
        assert!(w[1].meta.frame_id > w[0].meta.frame_id, "ids {} -> {}", w[0].meta.frame_id, w[1].meta.frame_id);
        assert!(w[1].meta.device_timestamp_ns > w[0].meta.device_timestamp_ns);
        assert!(w[1].meta.host_timestamp_ns >= w[0].meta.host_timestamp_ns);
        assert_eq!(w[1].meta.sequence, w[0].meta.sequence + 1);
    }
    for f in &frames {
        assert_eq!((f.meta.width, f.meta.height), (128, 64));
        assert_eq!(f.pixels.len(), 128 * 64);
        assert_eq!(f.meta.status, FrameStatus::Complete);
        assert_eq!(f.meta.bit_depth, 8);
        assert_eq!(f.meta.settings, applied);
        // The fake camera draws (x + y + frame_id) mod 255: checks row-major layout and id mapping.
        for (y, x) in [(0u64, 0u64), (0, 5), (3, 0), (10, 100), (63, 127)] {
            let expected = ((x + y + f.meta.frame_id) % 255) as u16;
            assert_eq!(f.pixels[(y * 128 + x) as usize], expected, "pixel ({x},{y}) of frame {}", f.meta.frame_id);
        }
    }
}

#[test]
fn fake_camera_streams_mono16() {
    let _g = serial();
    let mut cam = open_fake();
    cam.configure(&CameraSettings {
        roi: Some(Roi { x: 0, y: 0, width: 64, height: 32 }),
        binning: Some(Binning { horizontal: 1, vertical: 1 }),
        pixel_format: Some(PixelFormat::Mono16),
        frame_rate_hz: Some(100.0),
        trigger: Some(Trigger::FreeRun),
        ..Default::default()
    })
    .unwrap();
    cam.start().unwrap();
    let f = cam.next_frame(Duration::from_secs(2)).unwrap();
    cam.stop().unwrap();
    assert_eq!(f.meta.bit_depth, 16);
    assert_eq!(f.meta.settings.pixel_format, PixelFormat::Mono16);
    assert_eq!(f.pixels.len(), 64 * 32);
    assert_eq!(f.meta.status, FrameStatus::Complete);
    // At the default exposure (10 ms, gain 0) the ramp is unscaled: 256 (x + y + frame_id) mod 65535.
    for (y, x) in [(0u64, 0u64), (0, 5), (3, 0), (10, 40), (31, 63)] {
        let expected = ((256 * (x + y + f.meta.frame_id)) % 65535) as u16;
        assert_eq!(f.pixels[(y * 64 + x) as usize], expected, "pixel ({x},{y}) of frame {}", f.meta.frame_id);
    }
}

#[test]
fn out_of_range_exposure_is_refused_with_the_device_range() {
    let _g = serial();
    let mut cam = open_fake();
    let before = cam.applied_settings().unwrap().exposure_us;
    let e = cam.configure(&CameraSettings { exposure_us: Some(5.0), ..Default::default() }).unwrap_err();
    assert!(matches!(e, CameraError::OutOfRange { .. }), "{e:?}");
    assert_eq!(e.to_string(), "camera Fake_1: ExposureTimeAbs 5 us out of range [10, 10000000] us");
    let e = cam.configure(&CameraSettings { line_time_us: Some(5000.0), ..Default::default() }).unwrap_err();
    assert_eq!(e.to_string(), "camera Fake_1: LineTime 5000 us out of range [1, 1000] us");
    assert_eq!(cam.applied_settings().unwrap().exposure_us, before, "refused value was not written");
    // aravis' own range check is on too: a direct write outside the range fails.
    assert!(cam.raw().set_float("ExposureTimeAbs", 5.0).is_err());
}

#[test]
fn unsupported_enumeration_values_name_the_choices() {
    let _g = serial();
    let mut cam = open_fake();
    let e = cam
        .configure(&CameraSettings { trigger: Some(Trigger::Hardware { line: "Line7".into(), edge: Edge::Rising }), ..Default::default() })
        .unwrap_err()
        .to_string();
    assert!(e.contains("Fake_1") && e.contains("TriggerSource") && e.contains("Line7") && e.contains("Software"), "{e}");
}

#[test]
fn unknown_camera_id_is_a_clear_error() {
    let _g = serial();
    let e = AravisCamera::open("NoSuchCamera-42", &AravisOptions::default()).err().expect("must fail");
    assert!(matches!(e, CameraError::NotFound { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.starts_with("camera NoSuchCamera-42 not found on aravis"), "{msg}");
}

#[test]
fn missing_feature_in_profile_is_a_clear_error() {
    let _g = serial();
    let mut profile = rollcam_hw::camera::profile::CameraProfile::builtin("aravis-fake").unwrap();
    profile.name = "broken".into();
    profile.exposure.feature = "ExposureTime".into(); // the fake camera only has ExposureTimeAbs
    let e = AravisCamera::open("Fake_1", &AravisOptions { profile: Some(profile.clone()), ..Default::default() }).err().expect("must fail");
    assert_eq!(e.to_string(), "camera Fake_1: feature ExposureTime (for exposure_us) is not implemented by this camera (profile broken)");
    // Marked optional, the same profile opens with a warning but refuses the setting.
    profile.exposure.optional = true;
    let mut cam = AravisCamera::open("Fake_1", &AravisOptions { profile: Some(profile), ..Default::default() }).unwrap();
    let e = cam.configure(&CameraSettings { exposure_us: Some(100.0), ..Default::default() }).unwrap_err();
    assert!(matches!(e, CameraError::MissingFeature { .. }), "{e}");
}

#[test]
fn software_trigger_over_gige_fake_yields_exactly_the_triggered_frames() {
    let _g = serial();
    let _gv = start_gv_fake_camera("127.0.0.1", "RCAM01").expect("GigE fake camera");
    let mut cam = AravisCamera::open("127.0.0.1", &AravisOptions::default()).expect("open GigE fake at 127.0.0.1");
    assert_eq!(cam.profile().name, "aravis-fake");
    cam.configure(&CameraSettings {
        roi: Some(Roi { x: 0, y: 0, width: 64, height: 48 }),
        pixel_format: Some(PixelFormat::Mono8),
        shutter: Some(CameraShutter::Rolling),
        trigger: Some(Trigger::Software),
        ..Default::default()
    })
    .unwrap();
    assert_eq!(cam.applied_settings().unwrap().trigger, Trigger::Software);
    cam.start().unwrap();
    // Untriggered: nothing arrives.
    let e = cam.next_frame(Duration::from_millis(500)).unwrap_err();
    assert!(matches!(e, CameraError::Timeout { .. }), "{e}");
    let mut ids = Vec::new();
    for _ in 0..3 {
        cam.software_trigger().unwrap();
        let f = cam.next_frame(Duration::from_secs(3)).unwrap();
        assert_eq!(f.meta.status, FrameStatus::Complete);
        assert_eq!(f.pixels.len(), 64 * 48);
        ids.push(f.meta.frame_id);
    }
    // No extra frames after the three triggers.
    let e = cam.next_frame(Duration::from_millis(500)).unwrap_err();
    assert!(matches!(e, CameraError::Timeout { .. }), "{e}");
    cam.stop().unwrap();
    assert!(ids.windows(2).all(|w| w[1] > w[0]), "{ids:?}");
}

#[test]
fn gige_camera_vanishing_mid_stream_is_disconnected_not_a_hang() {
    let _g = serial();
    let gv = start_gv_fake_camera("127.0.0.1", "RCAM02").expect("GigE fake camera");
    let mut cam = AravisCamera::open("127.0.0.1", &AravisOptions::default()).expect("open GigE fake at 127.0.0.1");
    cam.configure(&CameraSettings {
        roi: Some(Roi { x: 0, y: 0, width: 32, height: 32 }),
        pixel_format: Some(PixelFormat::Mono8),
        frame_rate_hz: Some(50.0),
        trigger: Some(Trigger::FreeRun),
        ..Default::default()
    })
    .unwrap();
    cam.start().unwrap();
    cam.next_frame(Duration::from_secs(3)).expect("a frame while the camera is there");
    drop(gv); // the camera goes away
    let t0 = std::time::Instant::now();
    let e = loop {
        match cam.next_frame(Duration::from_millis(300)) {
            Ok(_) => assert!(t0.elapsed() < Duration::from_secs(2), "frames keep coming after the camera left"),
            Err(e) => break e,
        }
    };
    assert!(matches!(e, CameraError::Disconnected { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.contains("RCAM02: disconnected") && msg.contains("stopped answering"), "{msg}");
    assert!(t0.elapsed() < Duration::from_secs(15), "took {:?}", t0.elapsed());
}

/// The XML was written to `$TMPDIR/rollcam-fake-camera-<pid>.xml` with a plain write: a
/// link planted at that name was followed and its target overwritten.
#[test]
fn the_fake_cameras_xml_is_never_written_through_a_planted_link() {
    use rollcam_hw::camera::aravis::{fake_camera_xml_path, FAKE_CAMERA_GENICAM_XML};
    use std::os::unix::fs::PermissionsExt;
    let _g = serial();
    let predictable = std::env::temp_dir().join(format!("rollcam-fake-camera-{}.xml", std::process::id()));
    let decoy_dir = tempfile::tempdir().unwrap();
    let decoy = decoy_dir.path().join("decoy");
    std::fs::write(&decoy, b"decoy").unwrap();
    let planted = std::os::unix::fs::symlink(&decoy, &predictable);
    let path = fake_camera_xml_path();
    let _ = std::fs::remove_file(&predictable);
    assert!(planted.is_ok(), "a file already lay at the predictable name {}: {planted:?}", predictable.display());
    let path = path.unwrap();
    assert_eq!(std::fs::read(&decoy).unwrap(), b"decoy", "the link's target was overwritten");
    assert_ne!(path, predictable);
    assert_eq!(std::fs::read_to_string(&path).unwrap(), FAKE_CAMERA_GENICAM_XML);
    let folder = std::fs::metadata(path.parent().unwrap()).unwrap();
    assert_eq!(folder.permissions().mode() & 0o777, 0o700, "a private folder");
}
