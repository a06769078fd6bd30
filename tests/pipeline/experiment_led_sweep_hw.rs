//! The LED sweep's bench mode with no hardware: the LED controller emulator on a real
//! pseudo-terminal and the simulated camera `sim:led-array`, which renders the LEDs
//! from what the controller holds (read back over the link), not from the sweep's
//! own parameters. Also: a controller that never answers, and (feature `aravis`) the
//! same code path through libaravis' fake camera.

use crate::support::cli::json;
use rollcam::lab::led_sweep::{controller_scene, program_leds, BenchOptions};
use rollcam_hw::led::{ChannelConfig, Identity, LedController, LinkedEmulator, TriggerMode};
use serialport::SerialPort;
use std::path::Path;
use std::process::Command;
use std::sync::Mutex;

fn rollcam(args: &[&str], cache: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rollcam")).args(args).env("ROLLCAM_CACHE_DIR", cache).output().expect("run rollcam")
}

#[test]
fn two_period_sweep_through_the_emulator_and_the_simulated_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sweep");
    let out_s = out.to_str().unwrap();
    let o = rollcam(
        &[
            "experiment",
            "led-sweep",
            "--camera",
            "sim:led-array",
            "--led",
            "emulator",
            "--size",
            "small",
            "--periods-us",
            "2640,1320",
            "--iters",
            "40",
            "--out",
            out_s,
        ],
        tmp.path(),
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stdout}\n{stderr}");
    println!("{stdout}");

    let report = json(&out.join("report.json"));
    let rows = report["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    for (row, period) in rows.iter().zip([2640.0, 1320.0]) {
        let expected = 1e6 / period;
        assert_eq!(row["period_us"].as_f64(), Some(period));
        assert!((row["expected_frequency_hz"].as_f64().unwrap() - expected).abs() < 1e-6);
        let peak = row["measured_peak_hz"].as_f64().unwrap_or_else(|| panic!("no spectral peak at {period} us: {row}"));
        let bin = row["bin_hz"].as_f64().unwrap();
        assert!((peak - expected).abs() <= bin, "period {period} us: peak {peak} Hz, LED frequency {expected} Hz, bin {bin} Hz");
        assert_eq!(row["peak_within_one_bin"], true);
        // The four LEDs are seen where the target puts them.
        assert_eq!((row["pairs_resolved"].as_u64(), row["pairs"].as_u64()), (Some(3), Some(3)), "{row}");
        assert!(row["truth_temporal_contrast"].is_null() && row["psnr_db"].is_null(), "a bench capture has no truth");
        // The controller's readback: four channels at the programmed period, duty 0.5.
        let channels = row["led_readback"]["channels"].as_array().unwrap();
        assert_eq!(channels.len(), 4);
        for (i, ch) in channels.iter().enumerate() {
            assert_eq!(ch["channel"].as_u64(), Some(i as u64));
            assert_eq!(ch["period_us"].as_f64(), Some(period));
            assert_eq!(ch["width_us"].as_f64(), Some(period / 2.0));
            assert_eq!(ch["phase_us"].as_u64(), Some(0));
        }
        // The raw was recorded, with the LED settings in its metadata.
        let folder = out.join(row["folder"].as_str().unwrap());
        let capture = json(&folder.join("capture/capture.json"));
        assert_eq!(capture["sync"]["led"], row["led_readback"], "capture.json holds the readback");
        assert_eq!(capture["frames_recorded"].as_u64(), Some(1));
        assert_eq!(capture["camera"]["backend"], "sim");
        let frames: Vec<_> =
            std::fs::read_dir(folder.join("capture")).unwrap().filter_map(|e| e.ok()).filter(|e| e.path().extension().is_some_and(|x| x == "tiff")).collect();
        assert_eq!(frames.len(), 1, "one raw per period");
        for f in ["capture.toml", "raw.png", "rec/video.npy", "rec/summary.json", "analysis/analysis.json"] {
            assert!(folder.join(f).exists(), "{f} missing in {}", folder.display());
        }
    }
    assert!(rows[0]["measured_peak_hz"].as_f64() != rows[1]["measured_peak_hz"].as_f64());
    assert_eq!(report["bench"]["camera"], "sim:led-array");
    assert_eq!(report["bench"]["led_device"]["name"], "rollcam-led");
    assert_eq!(report["bench"]["leds"].as_u64(), Some(4));
    for f in ["report.md", "figure.png", "psf.tiff"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("on the bench") && md.contains("| 2640 |") && md.contains("| 1320 |"), "{md}");
    // The emulator's link is gone once the command ends.
    assert!(!stdout.is_empty());
}

#[test]
fn a_controller_that_does_not_answer_is_named_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    // A real pseudo-terminal with nobody reading the other end.
    let (_master, slave) = serialport::TTYPort::pair().expect("pseudo-terminal pair");
    let port = slave.name().expect("slave name");
    let out = tmp.path().join("sweep");
    let o = rollcam(
        &[
            "experiment",
            "led-sweep",
            "--camera",
            "sim:led-array",
            "--led",
            &port,
            "--size",
            "small",
            "--periods-us",
            "2640,1320",
            "--iters",
            "5",
            "--out",
            out.to_str().unwrap(),
        ],
        tmp.path(),
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(stderr.contains(&port) && stderr.contains("did not answer"), "{stderr}");
    assert!(!out.exists(), "nothing may be written when the controller is silent");
}

#[test]
fn the_simulated_target_is_what_the_controller_holds() {
    let tmp = tempfile::tempdir().unwrap();
    let link = tmp.path().join("ttyLED");
    let emu = LinkedEmulator::create(&link, Identity::default()).unwrap();
    let ctrl = Mutex::new(LedController::open(link.to_str().unwrap(), rollcam_hw::led::DEFAULT_BAUD).unwrap());
    let opts = BenchOptions { phases_us: vec![0, 100, 200, 300], ..BenchOptions::default() };
    let sync = program_leds(&ctrl, &opts, 1980).unwrap();
    assert_eq!(sync.channels.len(), 4);
    assert_eq!(sync.trigger, TriggerMode::Software);
    let scene = controller_scene(&ctrl, 64, 80, 6.0).unwrap();
    assert_eq!(scene.leds(), 4);
    for l in 0..4 {
        assert_eq!(scene.period_us(l), 1980.0);
        // LED l rises at 100 l us: off just before, on just after.
        let rise = 100.0 * l as f64;
        assert_eq!(scene.waveform(l, rise, rise + 1.0), 1.0, "LED {l}");
        if l > 0 {
            assert_eq!(scene.waveform(l, rise - 1.0, rise), 0.0, "LED {l}");
        }
    }
    // The device, not the sweep, decides: change channel 1 behind the sweep's back.
    {
        let mut c = ctrl.lock().unwrap();
        c.stop().unwrap();
        c.configure(1, ChannelConfig::square(2640)).unwrap();
        c.disable(3).unwrap();
        c.arm(TriggerMode::Software).unwrap();
        c.trigger().unwrap();
    }
    let scene = controller_scene(&ctrl, 64, 80, 6.0).unwrap();
    assert_eq!(scene.leds(), 3);
    assert_eq!((scene.period_us(0), scene.period_us(1), scene.period_us(2)), (1980.0, 2640.0, 1980.0));
    assert_eq!(emu.emulator().device().channel(1).map(|(on, c)| (on, c.period_us)), Some((true, 2640)));
    // Stopped: the LEDs are dark, and the simulated camera says so instead of inventing light.
    ctrl.lock().unwrap().stop().unwrap();
    let e = controller_scene(&ctrl, 64, 80, 6.0).err().unwrap();
    assert!(e.contains("IDLE") && e.contains("dark") && e.contains("ttyLED"), "{e}");
}

/// libaravis' fake camera cannot show LEDs; this checks that the real-camera path
/// (camera settings from the capture description, ROI, recording, LED readback in the
/// metadata, reconstruction of the recorded file, report) runs through it.
#[cfg(feature = "aravis")]
#[test]
fn the_real_camera_path_runs_through_the_aravis_fake_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let (rows, cols) = (48usize, 64usize);
    let config = tmp.path().join("bench.toml");
    // The fake camera scales its ramp by 1 + gain + log10(exposure / 10 ms), all zero at
    // gain 0 below 1 ms (a raw with no light is refused): 10 ms gives the ramp as drawn.
    std::fs::write(&config, format!("rows = {rows}\ncols = {cols}\nline_time_us = 220.0\nexposure_us = 10000.0\nshutter = \"dual\"\n")).unwrap();
    let psf = rollcam::sim::lenslet_psf(rows, cols, &rollcam::sim::LensletParams::default(), 3).unwrap();
    let peak = psf.iter().cloned().fold(0.0f32, f32::max);
    let psf = psf.mapv(|v| v / peak * 50_000.0 + 100.0).insert_axis(ndarray::Axis(2));
    let psf_path = tmp.path().join("psf.tiff");
    rollcam::io::write_tiff_u16(&psf_path, psf.view()).unwrap();
    let out = tmp.path().join("sweep");
    let roi = format!("0,0,{cols},{rows}");
    let o = rollcam(
        &[
            "experiment",
            "led-sweep",
            "--camera",
            "aravis:Fake_1",
            "--led",
            "emulator",
            "--psf",
            psf_path.to_str().unwrap(),
            "--config",
            config.to_str().unwrap(),
            "--roi",
            &roi,
            "--led-pixel",
            "24,20",
            "--led-pixel",
            "24,28",
            "--led-pixel",
            "24,36",
            "--led-pixel",
            "24,44",
            "--periods-us",
            "2640",
            "--iters",
            "5",
            "--out",
            out.to_str().unwrap(),
        ],
        tmp.path(),
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stdout}\n{stderr}");
    let report = json(&out.join("report.json"));
    assert_eq!(report["bench"]["camera"], "aravis:Fake_1");
    assert_eq!(report["sensor"], serde_json::json!([rows, cols]));
    let capture = json(&out.join("period-2640us/capture/capture.json"));
    assert_eq!(capture["camera"]["backend"], "aravis");
    assert_eq!(capture["sync"]["led"]["channels"].as_array().unwrap().len(), 4);
    assert_eq!(capture["applied"]["roi"]["width"].as_u64(), Some(cols as u64));
    assert!((capture["applied"]["exposure_us"].as_f64().unwrap() - 10_000.0).abs() < 1.0);
    assert!(out.join("period-2640us/rec/video.npy").exists() && out.join("report.md").exists());
    assert_eq!(report["rows"][0]["pairs"].as_u64(), Some(3), "the four given LED pixels are analysed");

    // At 660 us the fake camera's frames are all zero: the sweep is refused naming the
    // capture (no light above the dark), not solved into an all-zero video.
    let dark = tmp.path().join("dark.toml");
    std::fs::write(&dark, std::fs::read_to_string(&config).unwrap().replace("exposure_us = 10000.0", "exposure_us = 660.0")).unwrap();
    let o = rollcam(
        &[
            "experiment",
            "led-sweep",
            "--camera",
            "aravis:Fake_1",
            "--led",
            "emulator",
            "--psf",
            psf_path.to_str().unwrap(),
            "--config",
            dark.to_str().unwrap(),
            "--roi",
            &roi,
            "--periods-us",
            "2640",
            "--iters",
            "5",
            "--out",
            tmp.path().join("sweep2").to_str().unwrap(),
        ],
        tmp.path(),
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("frame_000000") && stderr.contains("no pixel is above the dark level"), "{stderr}");
    // What was recorded before the refusal is kept.
    assert!(tmp.path().join("sweep2/period-2640us/capture/capture.json").exists());
}
