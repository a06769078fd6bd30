//! The bench's second, global-shutter key-frame camera (`--keyframe-camera SPEC` of
//! `rollcam capture` and `rollcam run`): fired with every rolling-shutter frame at the
//! requested times, its frames recorded beside the raw ones with their device
//! timestamps and described by `[[keyframes]]` tables, so each raw frame reconstructs
//! with its own key frames.
//!
//! [`KeyedCamera`] wraps the main camera (it is a [`Camera`] itself, so the recorder of
//! `capture` and the acquisition thread of `run` drive it unchanged). For raw frame
//! `N` (its sequence number) it writes, beside `frame_NNNNNN.tiff`:
//!
//! * `keyframe_NNNNNN_JJ.tiff`: key frame `J` (16-bit), and on a device
//!   `keyframe_NNNNNN_JJ.json`, the key camera's frame metadata (device and host
//!   timestamps, applied settings);
//! * `frame_NNNNNN.toml`: the capture description of raw frame `N`, its
//!   `[[keyframes]]` tables included, with `[sync.keyframe_camera]` saying how the
//!   times were found.
//!
//! **Times.** A table's `start_us` is on the capture's time axis: `0` when the raw's
//! first row starts exposing (video frame 0 begins). With the [`KeyClock::Shared`]
//! clock it is measured: the key frame's device timestamp minus the raw frame's, both
//! marking the start of an exposure (the raw's first row). That holds only when both
//! cameras stamp with one clock (the simulated bench's; cameras synchronised by
//! PTP/IEEE 1588). Otherwise ([`KeyClock::Commanded`], the default on devices) the two
//! device clocks cannot be related: the tables carry the commanded times (the software
//! trigger's delays, or the times the pulser was programmed with) and say so; the
//! device timestamps are still recorded in the sidecars.
//!
//! **Triggers.** Software (the fake and simulated cameras): rollcam fires the key
//! camera at each requested delay after it fires the main camera (`--trigger software`
//! on the main camera; a free-running main camera gives no start to count from, so
//! the delays then count from when rollcam asks for the frame). Hardware
//! (`hardware:<line>[:edge]`): the key camera waits for one edge per requested time on
//! that input line, wired from the main camera's exposure-output line or an LED pulser
//! channel programmed with those delays; rollcam fires nothing.
//!
//! The simulated key camera (`sim`, `sim:<name>`) sees the simulated main camera's
//! scene: each key frame is rendered from the truth video of the raw frame it goes with
//! ([`crate::sim::keyframe`]), on the simulated clock (times measured = commanded).

use crate::lab::camera::{open_camera, CameraOptions, CameraTarget, OpenCamera};
use crate::model::capture::CaptureConfig;
use crate::model::keyframe::KeyFrameRef;
use crate::sim::keyframe::{KeyFrameParams, KeyFramePlan, KeyTime};
use anyhow::{anyhow, bail, Context};
use ndarray::Axis;
use rollcam_hw::camera::{AppliedSettings, Camera, CameraError, CameraInfo, CameraSettings, Capabilities, Frame, FrameStatus, SensorGeometry, Trigger};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// How a key frame's start is found on the capture's time axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyClock {
    /// Measured: the key frame's device timestamp minus the raw frame's (both cameras
    /// stamp with one clock).
    Shared,
    /// The commanded times (the two device clocks cannot be related).
    Commanded,
}

impl std::str::FromStr for KeyClock {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "shared" => Ok(KeyClock::Shared),
            "commanded" => Ok(KeyClock::Commanded),
            other => Err(format!("'{other}': expected shared (both cameras stamp with one clock) or commanded")),
        }
    }
}

impl KeyClock {
    fn name(self) -> &'static str {
        match self {
            KeyClock::Shared => "shared",
            KeyClock::Commanded => "commanded",
        }
    }
}

/// The key-frame camera a command asks for.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyCameraRequest {
    /// `--keyframe-camera`: the simulated key camera or a device.
    pub target: CameraTarget,
    /// `--keyframes`: when each key frame starts, per raw frame (as `simulate`'s).
    pub times: Vec<KeyTime>,
    /// `--keyframe-exposure-us`; `None`: one video frame time.
    pub exposure_us: Option<f64>,
    /// `--keyframe-trigger`: software, or hardware:<line>[:edge].
    pub trigger: Trigger,
    /// `--keyframe-clock`; `None`: shared on the simulated key camera, commanded on a device.
    pub clock: Option<KeyClock>,
    /// How long to wait for each key frame.
    pub frame_timeout: Duration,
}

impl KeyCameraRequest {
    /// The flags' request, checked against the main camera's spec: a spec that parses,
    /// names another device than `--camera`, a trigger that fires once per key frame,
    /// a simulated key camera beside the simulated main camera only.
    pub fn new(spec: &str, main: &CameraTarget, times: &[String], exposure_us: Option<f64>, trigger: &str) -> anyhow::Result<KeyCameraRequest> {
        let target = CameraTarget::parse(spec).map_err(|e| anyhow!("--keyframe-camera {spec}: {e}"))?;
        if target == *main {
            bail!("--keyframe-camera {spec}: the same device as --camera; expected the second, global-shutter camera");
        }
        match (&target, main) {
            (CameraTarget::Replay(_), _) => bail!("--keyframe-camera {spec}: a recording cannot be triggered; expected sim or a device (aravis:<id>)"),
            (CameraTarget::Simulated { .. }, CameraTarget::Simulated { .. }) | (CameraTarget::Device(_), _) => {}
            (CameraTarget::Simulated { .. }, _) => {
                bail!("--keyframe-camera {spec}: the simulated key camera sees the simulated main camera's scene; expected --camera sim[:<scene>]")
            }
        }
        let times = if times.is_empty() { vec![KeyTime::First] } else { times.iter().map(|t| KeyTime::parse(t)).collect::<Result<_, _>>().map_err(flag)? };
        if let Some(v) = exposure_us.filter(|v| !(v.is_finite() && *v > 0.0)) {
            bail!("--keyframe-exposure-us = {v}: expected a positive exposure in microseconds");
        }
        let trigger: Trigger = trigger.parse().map_err(|e: String| anyhow!("--keyframe-trigger: {e}"))?;
        if trigger == Trigger::FreeRun {
            bail!("--keyframe-trigger free-run: the key camera fires with each raw frame; expected software or hardware:<line>[:edge]");
        }
        if matches!(target, CameraTarget::Simulated { .. }) && trigger != Trigger::Software {
            bail!("--keyframe-trigger {trigger}: the simulated key camera has no input lines; expected software");
        }
        Ok(KeyCameraRequest { target, times, exposure_us, trigger, clock: None, frame_timeout: Duration::from_secs(5) })
    }

    /// The clock the tables' times come from.
    pub fn clock(&self) -> KeyClock {
        self.clock.unwrap_or(match self.target {
            CameraTarget::Simulated { .. } => KeyClock::Shared,
            _ => KeyClock::Commanded,
        })
    }

    /// The trigger chain's link to the key camera from the main camera `main` (for
    /// `capture.json`): rollcam's software trigger, or the wired input line.
    pub fn trigger_link(&self, main: &str) -> rollcam_hw::record::TriggerLink {
        let times: Vec<String> = self.times.iter().map(|t| t.label()).collect();
        let source = match &self.trigger {
            Trigger::Hardware { .. } => format!("{main} exposure output or an LED pulser channel (wired)"),
            _ => format!("rollcam software trigger, after {main}'s"),
        };
        rollcam_hw::record::TriggerLink {
            source,
            target: format!("{} ({})", self.target.spec(), self.trigger),
            note: Some(format!("key frames at {} (--keyframes), clock {}", times.join(", "), self.clock().name())),
        }
    }

    /// The key frames' windows for raw frames described by `cfg`: each inside the video
    /// (`--keyframes` and `--keyframe-exposure-us` named when not).
    pub fn plan(&self, cfg: &CaptureConfig) -> anyhow::Result<KeyFramePlan> {
        let timing = cfg.timing();
        let frames = timing.weights().context("the capture's timing")?.frames();
        let (rows, cols) = cfg.grid();
        let params = KeyFrameParams { times: self.times.clone(), exposure_us: self.exposure_us, ..KeyFrameParams::default() };
        params.plan((frames, rows, cols), timing.frame_time_us()).map_err(flag)
    }
}

/// A simulator's complaint about a key-frame value, naming its flag.
fn flag(e: crate::sim::SimError) -> anyhow::Error {
    match &e {
        crate::sim::SimError::Invalid { field, value, expected } => anyhow!("--{} = {value}: expected {expected}", field.replace('_', "-")),
        _ => e.into(),
    }
}

/// File name of key frame `j` of raw frame `sequence`.
pub fn keyframe_file(sequence: u64, j: usize) -> String {
    format!("keyframe_{sequence:06}_{j:02}.tiff")
}

/// File name of raw frame `sequence`'s capture description (its key frames' tables).
pub fn frame_description(sequence: u64) -> String {
    format!("frame_{sequence:06}.toml")
}

/// The capture description beside a recorded raw frame (`frame_NNNNNN.tiff` ->
/// `frame_NNNNNN.toml`), when there is one.
pub fn description_beside(raw: &Path) -> Option<PathBuf> {
    Some(raw.with_extension("toml")).filter(|p| p.is_file())
}

/// The `[[keyframes]]` tables and `[sync.keyframe_camera]` of raw frame `sequence`
/// recorded in `dir`, into `cfg` (the description written as the folder's
/// `capture.toml`).
pub fn with_recorded_keyframes(dir: &Path, sequence: u64, mut cfg: CaptureConfig) -> anyhow::Result<CaptureConfig> {
    let frame = CaptureConfig::load(&dir.join(frame_description(sequence)))?;
    cfg.keyframes = frame.keyframes;
    if let Some(t) = frame.sync.as_ref().and_then(|s| s.get("keyframe_camera")) {
        cfg.sync.get_or_insert_with(toml::Table::new).insert("keyframe_camera".into(), t.clone());
    }
    Ok(cfg)
}

/// Where key frames come from.
enum KeySource {
    /// Rendered from the simulated main camera's truth.
    Simulated,
    Device(Box<dyn Camera>),
}

/// The main camera with the key-frame camera fired beside it (see the module).
pub struct KeyedCamera {
    main: OpenCamera,
    key: KeySource,
    key_name: String,
    request: KeyCameraRequest,
    plan: KeyFramePlan,
    cfg: CaptureConfig,
    dir: PathBuf,
    fired_at: Option<Instant>,
}

/// A key camera's failure as a camera error naming it.
fn key_error(camera: &str, context: &str, e: impl std::fmt::Display) -> CameraError {
    CameraError::Device { camera: camera.to_string(), context: context.to_string(), message: e.to_string() }
}

impl KeyedCamera {
    /// `main`, already configured and described by `cfg`, with the key camera of
    /// `request` opened and configured (its exposure, its trigger); the files go into
    /// `dir` (the folder the raw frames are recorded in).
    pub fn open(main: OpenCamera, request: &KeyCameraRequest, cfg: &CaptureConfig, dir: &Path) -> anyhow::Result<KeyedCamera> {
        let key_name = request.target.spec();
        match (&request.target, &main) {
            (CameraTarget::Simulated { .. }, OpenCamera::Simulated(_)) => KeyedCamera::new(main, None, request, cfg, dir),
            (CameraTarget::Simulated { .. }, _) => bail!("--keyframe-camera {key_name}: expected --camera sim[:<scene>] beside the simulated key camera"),
            (target, _) => {
                let OpenCamera::Device(cam) = open_camera(target, CameraOptions::default())? else { bail!("--keyframe-camera {key_name}: not a device") };
                KeyedCamera::new(main, Some(cam), request, cfg, dir)
            }
        }
    }

    /// [`KeyedCamera::open`] with the key camera already open (`None`: the simulated
    /// key camera); a device is configured here and refused when it is the main camera.
    pub fn new(main: OpenCamera, key: Option<Box<dyn Camera>>, request: &KeyCameraRequest, cfg: &CaptureConfig, dir: &Path) -> anyhow::Result<KeyedCamera> {
        let plan = request.plan(cfg)?;
        let key_name = request.target.spec();
        let key = match key {
            None => KeySource::Simulated,
            Some(mut cam) => {
                let main_info = match &main {
                    OpenCamera::Simulated(c) => c.info().clone(),
                    OpenCamera::Device(c) => c.info().clone(),
                };
                let same_serial = main_info.serial.is_some() && main_info.serial == cam.info().serial && main_info.backend == cam.info().backend;
                if cam.info().spec() == main_info.spec() || same_serial {
                    bail!("--keyframe-camera {key_name}: the same device as --camera ({}); expected the second, global-shutter camera", main_info.spec());
                }
                let settings = CameraSettings { exposure_us: Some(plan.exposure_us), trigger: Some(request.trigger.clone()), ..CameraSettings::default() };
                let applied = cam.configure(&settings).with_context(|| format!("configuring the key-frame camera {key_name}"))?;
                if (applied.exposure_us - plan.exposure_us).abs() > 1e-6 * plan.exposure_us.max(1.0) {
                    tracing::warn!(
                        asked = plan.exposure_us,
                        applied = applied.exposure_us,
                        "the key camera applied another exposure; its tables carry the applied one"
                    );
                }
                KeySource::Device(cam)
            }
        };
        Ok(KeyedCamera { main, key, key_name, request: request.clone(), plan, cfg: cfg.clone(), dir: dir.to_path_buf(), fired_at: None })
    }

    /// The main camera back (the key camera closed).
    pub fn into_main(self) -> OpenCamera {
        self.main
    }

    /// The key frames' planned starts and exposure, microseconds.
    pub fn plan(&self) -> &KeyFramePlan {
        &self.plan
    }

    /// The key camera's spec.
    pub fn key_name(&self) -> &str {
        &self.key_name
    }

    /// Fire the key camera's software triggers at the planned delays after `t0`
    /// (nothing on a hardware trigger or the simulated key camera).
    fn fire(&mut self, t0: Instant) -> Result<(), CameraError> {
        let KeySource::Device(cam) = &mut self.key else { return Ok(()) };
        if self.request.trigger != Trigger::Software {
            return Ok(());
        }
        let mut starts = self.plan.starts_us.clone();
        starts.sort_by(f64::total_cmp);
        for s in starts {
            let due = t0 + Duration::from_secs_f64(s.max(0.0) / 1e6);
            std::thread::sleep(due.saturating_duration_since(Instant::now()));
            cam.software_trigger()?;
        }
        Ok(())
    }

    /// The key frames fired for a raw frame the main camera dropped, read and let go
    /// (so they are not taken for the next frame's).
    fn discard(&mut self) {
        if let KeySource::Device(cam) = &mut self.key {
            for _ in 0..self.plan.starts_us.len() {
                if cam.next_frame(self.request.frame_timeout).is_err() {
                    break;
                }
            }
            tracing::warn!(camera = %self.key_name, "raw frame dropped: its key frames are not recorded");
        }
    }

    /// Record the key frames of raw frame `frame` and its capture description.
    fn record(&mut self, frame: &Frame) -> anyhow::Result<()> {
        let seq = frame.meta.sequence;
        let (refs, sync) = match &mut self.key {
            KeySource::Simulated => {
                let (refs, gain) = self.simulated(seq)?;
                let mut sync = sync_table(&self.key_name, &self.request, KeyClock::Shared, Vec::new());
                sync.insert("true_gain".into(), gain.into());
                (refs, sync)
            }
            KeySource::Device(_) => self.device_frames(frame)?,
        };
        let mut cfg = CaptureConfig { keyframes: refs, ..self.cfg.clone() };
        cfg.sync.get_or_insert_with(toml::Table::new).insert("keyframe_camera".into(), sync.into());
        cfg.validate().with_context(|| format!("raw frame {seq}: its key frames' tables"))?;
        let path = self.dir.join(frame_description(seq));
        refuse_existing(&path)?;
        crate::io::write_text_atomic(&path, &cfg.to_toml())?;
        Ok(())
    }

    /// Key frames rendered from the simulated main camera's truth of its last frame, and
    /// their true gain (key counts per video unit; the tables leave it to the fit).
    fn simulated(&self, seq: u64) -> anyhow::Result<(Vec<KeyFrameRef>, f64)> {
        let OpenCamera::Simulated(cam) = &self.main else { bail!("the simulated key camera needs the simulated main camera") };
        let r = cam.renderer();
        let truth = r.last_truth().context("the simulated main camera rendered no frame yet")?;
        let keys = self.plan.render(truth.view(), r.conversion_gain_adu_per_e(), r.seed().wrapping_add(seq)).map_err(flag)?;
        let mut refs = keys.refs;
        for (j, (r, img)) in refs.iter_mut().zip(&keys.images).enumerate() {
            r.file = keyframe_file(seq, j);
            let path = self.dir.join(&r.file);
            refuse_existing(&path)?;
            crate::io::write_tiff_u16(&path, img.view().insert_axis(Axis(2)))?;
        }
        Ok((refs, keys.gain))
    }

    /// The key frames the device delivered for raw frame `frame`, written with their
    /// metadata; their tables and the sync description.
    fn device_frames(&mut self, frame: &Frame) -> anyhow::Result<(Vec<KeyFrameRef>, toml::Table)> {
        let KeySource::Device(cam) = &mut self.key else { unreachable!("a device key camera") };
        let seq = frame.meta.sequence;
        let clock = self.request.clock();
        let mut refs = Vec::new();
        let mut stamps = Vec::new();
        // Key frames arrive in time order: the `j`-th is the `j`-th earliest time.
        let mut commanded_us = self.plan.starts_us.clone();
        commanded_us.sort_by(f64::total_cmp);
        for (j, &commanded) in commanded_us.iter().enumerate() {
            let key = cam.next_frame(self.request.frame_timeout).with_context(|| format!("key frame {j} of raw frame {seq}"))?;
            if key.meta.status != FrameStatus::Complete {
                bail!("key frame {j} of raw frame {seq} arrived {:?} from {}", key.meta.status, self.key_name);
            }
            let file = keyframe_file(seq, j);
            write_key_frame(&self.dir, &file, &key)?;
            let measured = (key.meta.device_timestamp_ns as f64 - frame.meta.device_timestamp_ns as f64) / 1e3;
            stamps.push(toml::Value::from(key.meta.device_timestamp_ns as i64));
            let start_us = match clock {
                KeyClock::Shared => measured,
                KeyClock::Commanded => commanded,
            };
            refs.push(KeyFrameRef { file, start_us, exposure_us: key.meta.settings.exposure_us, dark_level: None, gain: None, affine: None, psf: None });
        }
        let (frames, t_f) = (self.plan.video_frames(), self.plan.frame_time_us());
        let outside: Vec<usize> = (0..refs.len()).filter(|&j| refs[j].time_weights(frames, t_f).is_err()).collect();
        if !outside.is_empty() {
            tracing::warn!(raw = seq, ?outside, "key frames outside the raw frame's video window: recorded, left out of the tables");
        }
        let kept = refs.into_iter().enumerate().filter(|(j, _)| !outside.contains(j)).map(|(_, r)| r).collect();
        let mut sync = sync_table(&self.key_name, &self.request, clock, stamps);
        sync.insert("raw_device_timestamp_ns".into(), (frame.meta.device_timestamp_ns as i64).into());
        Ok((kept, sync))
    }
}

/// Refuse to replace a file this command did not write.
fn refuse_existing(path: &Path) -> anyhow::Result<()> {
    if path.exists() {
        bail!("{}: already exists; a key frame's file is never replaced (record into a new folder)", path.display());
    }
    Ok(())
}

/// A key frame from a device as `dir/file` (16-bit) and its metadata beside it.
fn write_key_frame(dir: &Path, file: &str, key: &Frame) -> anyhow::Result<()> {
    let path = dir.join(file);
    refuse_existing(&path)?;
    let bytes = rollcam_hw::record::encode_tiff16(key.meta.width, key.meta.height, &key.pixels, &path)?;
    rollcam_hw::record::write_atomic(dir, file, &bytes)?;
    let json = file.replace(".tiff", ".json");
    rollcam_hw::record::write_atomic(dir, &json, &serde_json::to_vec_pretty(&key.meta)?)?;
    Ok(())
}

/// `[sync.keyframe_camera]`: the key camera, its trigger and how its times were found.
fn sync_table(name: &str, req: &KeyCameraRequest, clock: KeyClock, device_timestamps_ns: Vec<toml::Value>) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert("camera".into(), name.into());
    t.insert("trigger".into(), req.trigger.to_string().into());
    t.insert("clock".into(), clock.name().into());
    let note = match (clock, matches!(req.target, CameraTarget::Simulated { .. })) {
        (_, true) => "simulated key camera: rendered from the simulated scene's truth at the requested windows; times on the simulated clock",
        (KeyClock::Shared, false) => "start_us measured: key device timestamp minus the raw frame's (one clock, both marking an exposure start)",
        (KeyClock::Commanded, false) => {
            "start_us commanded: the two cameras' device clocks cannot be related; their timestamps are in the key frames' .json sidecars"
        }
    };
    t.insert("note".into(), note.into());
    if !device_timestamps_ns.is_empty() {
        t.insert("device_timestamps_ns".into(), device_timestamps_ns.into());
    }
    t
}

impl Camera for KeyedCamera {
    fn info(&self) -> &CameraInfo {
        match &self.main {
            OpenCamera::Simulated(c) => c.info(),
            OpenCamera::Device(c) => c.info(),
        }
    }
    fn geometry(&mut self) -> Result<SensorGeometry, CameraError> {
        self.main.camera().geometry()
    }
    fn capabilities(&mut self) -> Result<Capabilities, CameraError> {
        self.main.camera().capabilities()
    }
    fn configure(&mut self, settings: &CameraSettings) -> Result<AppliedSettings, CameraError> {
        self.main.camera().configure(settings)
    }
    fn applied_settings(&mut self) -> Result<AppliedSettings, CameraError> {
        self.main.camera().applied_settings()
    }
    fn start(&mut self) -> Result<(), CameraError> {
        if let KeySource::Device(cam) = &mut self.key {
            cam.start()?;
        }
        self.main.camera().start()
    }
    fn software_trigger(&mut self) -> Result<(), CameraError> {
        self.main.camera().software_trigger()?;
        self.fired_at = Some(Instant::now());
        Ok(())
    }
    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        let t0 = self.fired_at.take().unwrap_or_else(Instant::now);
        self.fire(t0).map_err(|e| key_error(&self.key_name, "software trigger of the key-frame camera", e))?;
        let frame = self.main.camera().next_frame(timeout)?;
        if frame.meta.status == FrameStatus::Dropped {
            self.discard();
        } else {
            self.record(&frame).map_err(|e| key_error(&self.key_name, "recording key frames", format!("{e:#}")))?;
        }
        Ok(frame)
    }
    fn stop(&mut self) -> Result<(), CameraError> {
        let key = match &mut self.key {
            KeySource::Device(cam) => cam.stop(),
            KeySource::Simulated => Ok(()),
        };
        self.main.camera().stop()?;
        key
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rollcam_hw::camera::simulated::{FrameRenderer, RenderError, SimulatedCamera, SimulatedConfig};
    use rollcam_hw::camera::SensorGeometry;

    struct Ramp;
    impl FrameRenderer for Ramp {
        fn geometry(&self) -> SensorGeometry {
            SensorGeometry { width: 16, height: 8, max_bit_depth: 16 }
        }
        fn render(&mut self, i: u64, s: &AppliedSettings) -> Result<Vec<u16>, RenderError> {
            let (w, h) = s.image_size();
            Ok((0..w * h).map(|p| (100 + p as u64 + i) as u16).collect())
        }
    }

    fn camera(id: &str) -> Box<dyn Camera> {
        Box::new(SimulatedCamera::new(Ramp, SimulatedConfig { id: id.into(), ..SimulatedConfig::default() }))
    }

    fn request(times: &[&str]) -> KeyCameraRequest {
        let times: Vec<String> = times.iter().map(|s| s.to_string()).collect();
        KeyCameraRequest::new("aravis:key", &CameraTarget::parse("aravis:raw").unwrap(), &times, None, "software").unwrap()
    }

    /// A main camera and a software-triggered key camera of the hardware crate's
    /// simulated backend, described by the main camera's applied timing.
    fn keyed(times: &[&str], dir: &Path) -> anyhow::Result<KeyedCamera> {
        let mut main = camera("raw");
        let applied = main.configure(&CameraSettings { trigger: Some(Trigger::Software), ..CameraSettings::default() })?;
        let cfg = crate::lab::hardware::capture_config(8, 16, &applied, &Default::default())?;
        KeyedCamera::new(OpenCamera::Device(main), Some(camera("key")), &request(times), &cfg, dir)
    }

    #[test]
    fn key_frames_are_recorded_in_time_order_with_their_tables() {
        let dir = tempfile::tempdir().unwrap();
        let mut cam = keyed(&["300", "first"], dir.path()).unwrap();
        assert_eq!(cam.plan().starts_us, vec![300.0, 0.0]);
        cam.start().unwrap();
        for seq in 0..2u64 {
            cam.software_trigger().unwrap();
            let frame = cam.next_frame(Duration::from_secs(1)).unwrap();
            assert_eq!(frame.meta.sequence, seq);
            let table = CaptureConfig::load(&dir.path().join(frame_description(seq))).unwrap();
            // Commanded (a device's default): the earliest first, whatever the order asked.
            let starts: Vec<f64> = table.keyframes.iter().map(|k| k.start_us).collect();
            assert_eq!(starts, vec![0.0, 300.0]);
            assert_eq!(table.keyframes[1].file, keyframe_file(seq, 1));
            let sync = &table.sync.as_ref().unwrap()["keyframe_camera"];
            assert_eq!((sync["clock"].as_str(), sync["camera"].as_str()), (Some("commanded"), Some("aravis:key")));
            assert_eq!(sync["device_timestamps_ns"].as_array().unwrap().len(), 2);
            for j in 0..2 {
                let key = crate::io::read_image(dir.path().join(keyframe_file(seq, j))).unwrap();
                assert_eq!(key.dim(), (8, 16, 1));
                assert!(dir.path().join(keyframe_file(seq, j).replace(".tiff", ".json")).is_file());
            }
        }
        cam.stop().unwrap();
        assert!(description_beside(&dir.path().join("frame_000001.tiff")).is_some());
        assert!(description_beside(&dir.path().join("frame_000002.tiff")).is_none());
    }

    #[test]
    fn a_file_already_there_is_never_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let planted = dir.path().join(keyframe_file(0, 0));
        std::fs::write(&planted, b"not ours").unwrap();
        let mut cam = keyed(&["first"], dir.path()).unwrap();
        cam.start().unwrap();
        cam.software_trigger().unwrap();
        let e = cam.next_frame(Duration::from_secs(1)).unwrap_err().to_string();
        assert!(e.contains("keyframe_000000_00.tiff: already exists"), "{e}");
        assert_eq!(std::fs::read(&planted).unwrap(), b"not ours");
        assert!(!dir.path().join(frame_description(0)).exists());
    }

    #[test]
    fn requests_are_refused_by_name() {
        let main = CameraTarget::parse("aravis:Fake_1").unwrap();
        let e = |spec: &str, times: &[&str], trigger: &str| {
            let times: Vec<String> = times.iter().map(|s| s.to_string()).collect();
            KeyCameraRequest::new(spec, &main, &times, None, trigger).unwrap_err().to_string()
        };
        assert!(e("aravis:Fake_1", &[], "software").contains("the same device as --camera"));
        assert!(e("Fake_2", &[], "software").starts_with("--keyframe-camera Fake_2: camera spec"));
        assert!(e("sim", &[], "software").contains("expected --camera sim"));
        assert!(e("aravis:Key", &["soon"], "software").starts_with("--keyframes = 'soon'"));
        assert!(e("aravis:Key", &[], "free-run").starts_with("--keyframe-trigger free-run"));
        assert!(e("aravis:Key", &[], "line0").starts_with("--keyframe-trigger: trigger 'line0'"));
        let ok = KeyCameraRequest::new("aravis:Key", &main, &[], None, "hardware:Line0").unwrap();
        assert_eq!((ok.times.clone(), ok.clock()), (vec![KeyTime::First], KeyClock::Commanded));
        let sim = KeyCameraRequest::new("sim", &CameraTarget::parse("sim:led-array").unwrap(), &[], Some(100.0), "software").unwrap();
        assert_eq!(sim.clock(), KeyClock::Shared);
        assert_eq!("wall".parse::<KeyClock>().unwrap_err(), "'wall': expected shared (both cameras stamp with one clock) or commanded");
    }
}
