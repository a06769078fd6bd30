//! The LED sweep on the bench: an LED controller and a camera. For each period,
//! program the controller and verify its readback ([`program_leds`]), record one raw
//! with the camera (on disk first, LED readback in the capture metadata), reconstruct
//! that recorded file and analyse it with the analysis layer's LED sweep
//! ([`crate::analysis::led_sweep`]); [`controller_scene`] renders the controller's
//! state for a simulated camera.

use crate::analysis::led_sweep::{
    analyse_period, check_periods, compose_figure, io_err, led_pixels, other, period_folder, write_report, Acquired, BenchInfo, SweepOptions, SweepReport,
    SweepRow,
};
use crate::analysis::report::AnalysisError;
use crate::model::capture::CaptureConfig;
use crate::sim::{LedArray, LedLine};
use crate::solve::reconstruct::Hooks;
use ndarray::Array3;
use rollcam_hw::camera::{Camera, CameraSettings, FrameStatus, Trigger};
use rollcam_hw::led::{ChannelConfig, LedController, LedSync, RunState, TriggerMode};
use rollcam_hw::record::{CaptureReader, CaptureSession, Recorder, SyncInfo, TriggerLink};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use std::time::Instant;

/// How a bench sweep drives the LEDs.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// LEDs driven: controller channels `0..leds` (the paper: 4).
    pub leds: usize,
    /// High fraction of each period.
    pub duty: f64,
    /// First rise after the trigger, microseconds: one value for all LEDs or one per LED.
    pub phases_us: Vec<u32>,
    /// What starts the controller: `Software` (the host's `TRIG`, just before the
    /// capture) or an edge of the camera's exposure output (`Rising`/`Falling`).
    pub led_trigger: TriggerMode,
    /// How long to wait for the frame.
    pub frame_timeout: Duration,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions { leds: 4, duty: 0.5, phases_us: vec![0], led_trigger: TriggerMode::Software, frame_timeout: Duration::from_secs(10) }
    }
}

/// The bench of an LED sweep: a camera, the LED controller (shared, so a simulated
/// camera can read the controller's state too), the PSF and the capture description.
pub struct SweepBench<'a> {
    pub camera: &'a mut dyn Camera,
    /// Camera as given on the command line.
    pub camera_name: String,
    /// Settings applied before the sweep (timing from the capture description).
    pub settings: CameraSettings,
    pub led: Arc<Mutex<LedController>>,
    /// PSF in counts, `rows x cols x channels`, as measured (dark level included).
    pub psf: Array3<f32>,
    pub psf_name: String,
    /// The PSF is a calibration's (already dark-subtracted).
    pub psf_clean: bool,
    pub cfg: CaptureConfig,
    pub config_name: String,
    /// LED pixels on the sensor when known (a simulated target); else the brightest
    /// spots of each reconstruction.
    pub centres: Option<Vec<(usize, usize)>>,
}

fn led_err(e: impl std::fmt::Display) -> AnalysisError {
    other("LED controller", e)
}

fn lock(led: &Mutex<LedController>) -> std::sync::MutexGuard<'_, LedController> {
    led.lock().unwrap_or_else(|p| p.into_inner())
}

/// The channel configuration of LED `i` at `period_us`.
fn led_config(b: &BenchOptions, i: usize, period_us: u32) -> Result<ChannelConfig, AnalysisError> {
    let mut c = ChannelConfig::with_duty(period_us, b.duty).map_err(|e| other("--duty", format!("{e} (period {period_us} us)")))?;
    c.phase_us = if b.phases_us.len() == 1 { b.phases_us[0] } else { b.phases_us[i] };
    c.validate().map_err(|e| other("--periods-us/--duty/--phase-us", format!("LED {i}, period {period_us} us: {e}")))?;
    Ok(c)
}

/// Program every LED at `period_us`, read the configuration back over the link and
/// check it, then arm (and with a software trigger, start) the controller.
pub fn program_leds(led: &Mutex<LedController>, b: &BenchOptions, period_us: u32) -> Result<LedSync, AnalysisError> {
    let mut c = lock(led);
    c.stop().map_err(led_err)?;
    let device = c.identify().map_err(led_err)?;
    let mut programmed = Vec::new();
    for i in 0..b.leds {
        let cfg = led_config(b, i, period_us)?;
        c.configure(i as u8, cfg).map_err(led_err)?;
        programmed.push(cfg);
    }
    for ch in b.leds as u8..device.channels {
        c.disable(ch).map_err(led_err)?;
    }
    let sync = c.sync_summary(b.led_trigger).map_err(led_err)?;
    let port = c.port_name().to_string();
    let read: Vec<(u8, ChannelConfig)> = sync.channels.iter().map(|ch| (ch.channel, ch.config)).collect();
    let want: Vec<(u8, ChannelConfig)> = programmed.iter().enumerate().map(|(i, cfg)| (i as u8, *cfg)).collect();
    if read != want {
        return Err(led_err(format!("{port}: readback differs from what was programmed: programmed {want:?}, read back {read:?}")));
    }
    c.arm(b.led_trigger).map_err(led_err)?;
    if b.led_trigger == TriggerMode::Software {
        c.trigger().map_err(led_err)?;
    }
    Ok(sync)
}

/// The LED target as the controller drives it, for a simulated camera: the enabled
/// channels' periods, duty and phases as read back over the link (`GET`), one LED per
/// channel in channel order, `spacing_px` apart. The controller must be running
/// (triggered): otherwise the LEDs would be dark, and that is reported.
pub fn controller_scene(led: &Mutex<LedController>, rows: usize, cols: usize, spacing_px: f64) -> Result<LedArray, String> {
    let mut c = lock(led);
    let port = c.port_name().to_string();
    let status = c.status().map_err(|e| e.to_string())?;
    if status.state != RunState::Running {
        return Err(format!("LED controller on {port} is {} (not running): the LEDs are dark", status.state.token()));
    }
    let sync = c.sync_summary(status.trigger.unwrap_or(TriggerMode::Software)).map_err(|e| e.to_string())?;
    if sync.channels.is_empty() {
        return Err(format!("LED controller on {port}: no channel enabled"));
    }
    let periods: Vec<f64> = sync.channels.iter().map(|ch| ch.config.period_us as f64).collect();
    let phases: Vec<f64> = sync.channels.iter().map(|ch| ch.config.phase_us as f64).collect();
    let duties: Vec<f64> = sync.channels.iter().map(|ch| ch.config.width_us as f64 / ch.config.period_us as f64).collect();
    if duties.iter().any(|d| (d - duties[0]).abs() > 1e-9) || sync.channels.iter().any(|ch| ch.config.pulse_count.is_some()) {
        return Err(format!("LED controller on {port}: the simulated target needs continuous waves of one duty, read {:?}", sync.channels));
    }
    LedArray::new(
        rows,
        cols,
        LedLine { leds: periods.len(), spacing_px, radius_px: 1.5, period_us: periods, duty: duties[0], phase_us: phases, e_per_us: 1000.0 },
    )
    .map_err(|e| e.to_string())
}

/// LED pixels of the simulated target for `n` LEDs (the geometry of [`controller_scene`]).
pub fn target_pixels(rows: usize, cols: usize, n: usize, spacing_px: f64) -> Result<Vec<(usize, usize)>, AnalysisError> {
    let leds =
        LedArray::new(rows, cols, LedLine { leds: n, spacing_px, radius_px: 1.5, period_us: vec![1000.0], duty: 0.5, phase_us: vec![0.0], e_per_us: 1000.0 })
            .map_err(|e| other("LED target", e))?;
    Ok(led_pixels(&leds, cols))
}

/// Record one frame into `dir` (a new capture folder) with the LED readback in its
/// metadata; returns the frame as read back from disk, `rows x cols x 1`.
fn record_one(bench: &mut SweepBench, b: &BenchOptions, sync: &LedSync, dir: &Path, note: String) -> Result<(Array3<f32>, PathBuf), AnalysisError> {
    let cam_err = |e: &dyn std::fmt::Display| other(&format!("camera {}", bench.camera_name), e);
    let cam = &mut *bench.camera;
    let applied = cam.applied_settings().map_err(|e| cam_err(&e))?;
    let mut session = CaptureSession::new(cam.info().clone());
    session.geometry = Some(cam.geometry().map_err(|e| cam_err(&e))?);
    session.requested = bench.settings.clone();
    session.applied = Some(applied.clone());
    session.frames_requested = Some(1);
    session.sync = SyncInfo {
        led_phase_us: Some(b.phases_us[0] as f64),
        line_time_us: applied.line_time_us,
        trigger_chain: applied
            .exposure_output_line
            .iter()
            .map(|line| TriggerLink {
                source: format!("{} {line} (ExposureActive)", cam.info().spec()),
                target: format!("led {}", sync.port),
                note: Some(format!("armed {}", b.led_trigger.token())),
            })
            .collect(),
        led: Some(serde_json::to_value(sync).expect("LED sync serialises")),
        notes: Some(note),
    };
    let mut rec = Recorder::create(dir, session).map_err(|e| other(&dir.display().to_string(), e))?;
    let grab = (|| {
        cam.start()?;
        if applied.trigger == Trigger::Software {
            cam.software_trigger()?;
        }
        cam.next_frame(b.frame_timeout)
    })();
    let stopped = cam.stop();
    let frame = match grab {
        Ok(f) => f,
        Err(e) => {
            let _ = rec.finish(Some(e.to_string()));
            return Err(cam_err(&e));
        }
    };
    let written = rec.write_frame(&frame).map_err(|e| other(&dir.display().to_string(), e));
    let status = frame.meta.status;
    let outcome = match (&written, status) {
        (Err(e), _) => Some(e.to_string()),
        (Ok(_), FrameStatus::Complete) => None,
        (Ok(_), s) => Some(format!("frame {} is {s:?}", frame.meta.sequence)),
    };
    rec.finish(outcome.clone()).map_err(|e| other(&dir.display().to_string(), e))?;
    let path = written?;
    if let Some(o) = outcome {
        return Err(cam_err(&format!("{o}: the recorded file is kept in {} but not reconstructed", dir.display())));
    }
    stopped.map_err(|e| cam_err(&e))?;
    // Reconstruct what is on disk, not what is in memory.
    let reader = CaptureReader::open(dir).map_err(|e| other(&dir.display().to_string(), e))?;
    let f = reader.read_frame(0).map_err(|e| other(&dir.display().to_string(), e))?;
    let (w, h) = (f.meta.width as usize, f.meta.height as usize);
    let raw = Array3::from_shape_vec((h, w, 1), f.pixels.iter().map(|&v| v as f32).collect()).map_err(|e| other(&dir.display().to_string(), e))?;
    Ok((raw, path))
}

/// The bench sweep: for each period, program the LEDs and verify the readback, record
/// one raw (to `OUT/period-<P>us/capture/`, LED readback in its `capture.json`),
/// reconstruct that file, analyse; then the report, as [`run_sweep`] writes it.
/// Nothing is written before the LED controller has answered and the camera has taken
/// its settings; `out` must be new or empty.
pub fn run_bench_sweep(
    opts: &SweepOptions,
    bench: &mut SweepBench,
    b: &BenchOptions,
    out: &Path,
    command: &str,
    hooks: &Hooks,
    on_period: &dyn Fn(&SweepRow),
) -> Result<SweepReport, AnalysisError> {
    check_periods(&opts.periods_us)?;
    if let Some(p) = opts.periods_us.iter().find(|p| (**p - p.round()).abs() >= 1e-9) {
        return Err(other("--periods-us", format!("{p}: the LED controller takes whole positive microseconds")));
    }
    if b.leds == 0 {
        return Err(other("--leds", "0: expected at least one LED"));
    }
    if let Some(c) = &bench.centres {
        if c.len() != b.leds {
            return Err(other("--led-pixel", format!("{} pixels for {} LEDs: give one per LED", c.len(), b.leds)));
        }
        if let Some(&(r, col)) = c.iter().find(|&&(r, col)| r >= bench.cfg.rows || col >= bench.cfg.cols) {
            return Err(other("--led-pixel", format!("{r},{col} is outside the {} x {} raw of {}", bench.cfg.rows, bench.cfg.cols, bench.config_name)));
        }
    }
    if b.phases_us.len() != 1 && b.phases_us.len() != b.leds {
        return Err(other("--phase-us", format!("{} values: expected one value or one per LED ({})", b.phases_us.len(), b.leds)));
    }
    for &p in &opts.periods_us {
        for i in 0..b.leds {
            led_config(b, i, p as u32)?;
        }
    }
    // The controller answers and has the channels; the camera takes the settings.
    let device = lock(&bench.led).identify().map_err(led_err)?;
    if b.leds > device.channels as usize {
        return Err(other("--leds", format!("{}: the LED controller on {} has {} channels", b.leds, lock(&bench.led).port_name(), device.channels)));
    }
    let applied = bench.camera.configure(&bench.settings).map_err(|e| other(&format!("camera {}", bench.camera_name), e))?;
    let mut cfg = bench.cfg.clone();
    let (w, h) = applied.image_size();
    if (h as usize, w as usize) != (cfg.rows, cfg.cols) {
        return Err(other(&bench.config_name, format!("rows = {}, cols = {}, but camera {} gives {h} x {w} images", cfg.rows, cfg.cols, bench.camera_name)));
    }
    // The camera's applied timing is what the raw holds.
    cfg.exposure_us = applied.exposure_us;
    if let Some(lt) = applied.line_time_us {
        cfg.line_time_us = lt;
    }
    cfg.validate().map_err(|e| other(&format!("{} with the camera's applied timing", bench.config_name), e))?;
    if out.exists() && std::fs::read_dir(out).map_err(|e| io_err(out, "read folder", e))?.next().is_some() {
        return Err(other(&out.display().to_string(), "the folder exists and is not empty: choose a new one (recorded captures are never overwritten)"));
    }
    std::fs::create_dir_all(out).map_err(|e| io_err(out, "create folder", e))?;

    let led_port = lock(&bench.led).port_name().to_string();
    let mut rows = Vec::new();
    let mut dirs = Vec::new();
    for &p in &opts.periods_us {
        let t0 = Instant::now();
        let dir = out.join(period_folder(p));
        let sync = program_leds(&bench.led, b, p as u32)?;
        tracing::info!(period_us = p, port = %led_port, "LEDs programmed and verified; capturing");
        let captured = record_one(bench, b, &sync, &dir.join("capture"), format!("led-sweep period {p} us"));
        let stopped = lock(&bench.led).stop().map_err(led_err);
        let (raw, raw_path) = captured?;
        stopped?;
        let acquired = Acquired {
            raw,
            raw_name: raw_path.display().to_string(),
            psf: bench.psf.clone(),
            psf_name: bench.psf_name.clone(),
            psf_clean: bench.psf_clean,
            cfg: cfg.clone(),
            config_name: bench.config_name.clone(),
            truth: None,
            centres: bench.centres.clone(),
            leds: b.leds,
            duty: b.duty,
            led_readback: Some(serde_json::to_value(&sync).expect("LED sync serialises")),
            capture: Some(format!("{}/capture", period_folder(p))),
        };
        let row = analyse_period(opts, p, acquired, &dir, hooks, t0)?;
        on_period(&row);
        rows.push(row);
        dirs.push(dir);
    }
    let figure = "figure.png".to_string();
    compose_figure(&dirs, &out.join(&figure))?;
    let frame_time_us = cfg.line_time_us * cfg.downsample.max(1) as f64 * cfg.binning.max(1) as f64;
    let report = SweepReport {
        options: opts.clone(),
        sensor: (cfg.rows, cfg.cols),
        exposure_us: cfg.exposure_us,
        line_time_us: cfg.line_time_us * cfg.downsample.max(1) as f64,
        frame_time_us,
        nyquist_hz: crate::analysis::theory::nyquist_hz(frame_time_us),
        exposure_first_zero_hz: crate::analysis::theory::exposure_first_zero_hz(cfg.exposure_us),
        rows,
        figure: figure.clone(),
        command: command.to_string(),
        bench: Some(BenchInfo {
            camera: bench.camera_name.clone(),
            led_port,
            led_device: serde_json::to_value(&device).expect("device info serialises"),
            leds: b.leds,
            duty: b.duty,
            phases_us: b.phases_us.clone(),
            led_trigger: b.led_trigger.token().to_string(),
            psf: bench.psf_name.clone(),
            config: bench.config_name.clone(),
        }),
    };
    write_report(out, &report)?;
    Ok(report)
}

/// How to run the sweep on the bench (appended to the documentation page).
pub const BENCH_HOWTO_MD: &str = r#"## On the bench

The same sweep runs with the LED controller and a camera: for each period the command
programs the controller (channels 0-3: square waves of that period, duty `--duty`,
phases `--phase-us`), reads every channel back over the link and stops if the readback
differs from what it sent, arms the controller, records one raw with the camera (to
`OUT/period-<P>us/capture/`, the controller's readback in `capture.json` under
`sync.led`), stops the LEDs, reconstructs the recorded file (not the frame in memory)
and analyses it. The report (`report.md`, `report.json`, `figure.png`) is the one above,
with a `bench` section; truth and PSNR stay empty. Nothing is written until the
controller has answered and the camera has taken its settings, and `OUT` must be new.

```sh
# Rehearsal, no hardware: the emulator on a pseudo-terminal and a simulated camera
# that renders the LEDs from the state the controller holds (read back over the link).
rollcam experiment led-sweep --camera sim:led-array --led emulator --size small \
    --periods-us 2640,1980,1320,660 --out sweep-rehearsal/

# The bench: DiffuserCam PSF and timing of the raw; exposure and line time are set on
# the camera from bench.toml, and the camera's applied values are used to reconstruct.
cargo build --release --features aravis
rollcam experiment led-sweep --camera aravis:<device id> --led /dev/ttyACM0 \
    --psf psf.tiff --config bench.toml --periods-us 2640,1980,1320,660 \
    --exposure-output-line Line1 --led-trigger rising --out sweep/
```

- `--led-trigger software` (default) starts the LEDs from the host just before the
  capture, so their phase relative to the first row is not known; `rising` (or
  `falling`) arms the controller on its trigger input, wired to the camera's
  exposure-active output (`--exposure-output-line`), so t = 0 is the first row's start.
- `--leds N`, `--duty D`, `--phase-us P | P0,P1,...`: the LEDs driven (controller
  channels 0..N) and their waveform; periods are whole microseconds.
- `--roi x,y,w,h`: a region of interest on a real camera (`rows`/`cols` of bench.toml
  must match it); `--camera-trigger`, `--frame-timeout-ms`, `--led-baud` as in
  `rollcam capture` and `rollcam led`.
- `--led-pixel ROW,COL` (once per LED, raw sensor pixels): where the LEDs are on a
  real camera; without it each reconstruction's brightest `N` spots are the LED regions.
- Tested with no hardware in `tests/pipeline/experiment_led_sweep_hw.rs`: a two-period sweep
  through the emulator and `sim:led-array` finds its spectral peaks at the programmed
  LED frequencies, a controller that does not answer is named and nothing is written,
  and (feature `aravis`) the real-camera path runs through libaravis' fake camera,
  which cannot show LEDs.
"#;
