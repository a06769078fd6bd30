//! GenICam cameras (GigE Vision, USB3 Vision) through the system libaravis.
//!
//! Settings are mapped to GenICam features through a [`CameraProfile`]. Range
//! checking is enabled in aravis ([`RangeCheckPolicy::Enable`]) and, before each
//! write, the device's own bounds are read so that an out-of-range request is
//! refused with the range in the message.
//!
//! The Aravis "Fake" interface (ids `Fake_*`) is enabled on demand with rollcam's
//! GenICam XML (`fixtures/genicam/rollcam-fake-camera.xml`, compiled in), which adds
//! a rolling-shutter model (SensorShutterMode, LineTime, LineSelector/LineSource)
//! to the stock fake camera.

use std::ffi::{CStr, CString};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use aravis::glib;
use aravis::prelude::*;
use aravis::{AccessCheckPolicy, BufferStatus, RangeCheckPolicy};

use super::device::Camera;
use super::error::{check_range, CameraError};
use super::profile::{CameraProfile, FeatureRef, LineTimeUnit};
use super::stream::{bytes_to_u16, host_now_ns, GapFiller};
use rollcam_files::frame::{
    AppliedSettings, Binning, CameraInfo, CameraSettings, CameraShutter, Capabilities, Edge, Frame, FrameMeta, FrameStatus, PixelFormat, Roi, SensorGeometry,
    Trigger,
};

/// The aravis bindings, for callers who need features rollcam does not wrap
/// (use with [`AravisCamera::raw`]; `use rollcam_hw::camera::aravis::arv::prelude::*`).
pub use ::aravis as arv;

/// rollcam's fake camera description (stock aravis fake camera + rolling-shutter features).
pub const FAKE_CAMERA_GENICAM_XML: &str = include_str!("../../../fixtures/genicam/rollcam-fake-camera.xml");

/// Serialises aravis' global device list, which is shared process-wide.
static ARAVIS_LOCK: Mutex<()> = Mutex::new(());
static FAKE_XML_PATH: OnceLock<PathBuf> = OnceLock::new();

/// Options for [`AravisCamera::open`].
#[derive(Debug, Clone, Default)]
pub struct AravisOptions {
    /// Profile to use; `None` picks one from the device's vendor and model.
    pub profile: Option<CameraProfile>,
    /// Number of stream buffers (default 8).
    pub n_buffers: Option<usize>,
}

fn lock() -> std::sync::MutexGuard<'static, ()> {
    ARAVIS_LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// The private folder holding the fake camera's XML, removed at exit.
static FAKE_XML_DIR: Mutex<Option<tempfile::TempDir>> = Mutex::new(None);

/// Removes the fake camera's XML and its folder (registered with `atexit`: runs on every
/// normal exit, an error's included).
extern "C" fn remove_fake_xml() {
    if let Ok(mut dir) = FAKE_XML_DIR.lock() {
        drop(dir.take());
    }
}

/// Write rollcam's fake-camera XML to a file and return its path (once per process).
/// The file lies in a fresh private folder (`tempfile`: an unpredictable name, mode
/// 0700, created exclusively), so a link planted in the temporary directory is never
/// followed, and the folder is removed when the process exits.
pub fn fake_camera_xml_path() -> Result<PathBuf, CameraError> {
    if let Some(p) = FAKE_XML_PATH.get() {
        return Ok(p.clone());
    }
    let mut slot = FAKE_XML_DIR.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(p) = FAKE_XML_PATH.get() {
        return Ok(p.clone());
    }
    let fail = |context: String, e: std::io::Error| CameraError::Device { camera: "Fake".into(), context, message: e.to_string() };
    let dir = tempfile::Builder::new()
        .prefix("rollcam-fake-camera-")
        .permissions(std::os::unix::fs::PermissionsExt::from_mode(0o700))
        .tempdir()
        .map_err(|e| fail(format!("creating a private folder for the GenICam XML in {}", std::env::temp_dir().display()), e))?;
    let path = dir.path().join("rollcam-fake-camera.xml");
    let written = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&path)
        .and_then(|mut f| std::io::Write::write_all(&mut f, FAKE_CAMERA_GENICAM_XML.as_bytes()));
    // On an error the folder is dropped (removed) here.
    written.map_err(|e| fail(format!("writing GenICam XML to {}", path.display()), e))?;
    if slot.replace(dir).is_none() {
        // SAFETY: registers a plain function without arguments; it only takes the lock.
        unsafe { libc::atexit(remove_fake_xml) };
    }
    Ok(FAKE_XML_PATH.get_or_init(|| path).clone())
}

/// Enable aravis' in-library Fake interface with rollcam's GenICam XML. Idempotent.
///
/// The XML file name is handed to aravis before the interface is enabled, as aravis
/// reads it when the fake device is first created.
pub fn enable_fake_interface() -> Result<PathBuf, CameraError> {
    static ENABLED: OnceLock<PathBuf> = OnceLock::new();
    if let Some(p) = ENABLED.get() {
        return Ok(p.clone());
    }
    let path = fake_camera_xml_path()?;
    let _g = lock();
    let p = ENABLED.get_or_init(|| {
        // aravis keeps the pointer: leak one CString for the life of the process.
        let c = CString::new(path.to_string_lossy().as_bytes()).expect("temp path has no NUL");
        let leaked: &'static CStr = Box::leak(c.into_boxed_c_str());
        let iface = CString::new("Fake").expect("no NUL");
        unsafe {
            aravis_sys::arv_set_fake_camera_genicam_filename(leaked.as_ptr());
            aravis_sys::arv_enable_interface(iface.as_ptr());
        }
        tracing::info!(xml = %path.display(), "enabled aravis Fake interface");
        path.clone()
    });
    Ok(p.clone())
}

fn cstr(p: *const std::os::raw::c_char) -> Option<String> {
    if p.is_null() {
        None
    } else {
        Some(unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned())
    }
}

/// List GenICam devices visible to aravis (all enabled interfaces).
pub fn discover() -> Vec<CameraInfo> {
    let _g = lock();
    discover_locked()
}

fn discover_locked() -> Vec<CameraInfo> {
    unsafe {
        aravis_sys::arv_update_device_list();
        let n = aravis_sys::arv_get_n_devices();
        (0..n)
            .filter_map(|i| {
                let id = cstr(aravis_sys::arv_get_device_id(i))?;
                Some(CameraInfo {
                    backend: "aravis".into(),
                    id,
                    vendor: cstr(aravis_sys::arv_get_device_vendor(i)),
                    model: cstr(aravis_sys::arv_get_device_model(i)),
                    serial: cstr(aravis_sys::arv_get_device_serial_nbr(i)),
                    address: cstr(aravis_sys::arv_get_device_address(i)),
                    protocol: cstr(aravis_sys::arv_get_device_protocol(i)),
                })
            })
            .collect()
    }
}

fn is_fake_id(id: &str) -> bool {
    id.starts_with("Fake_") || id == "Fake" || id.starts_with("Aravis-Fake")
}

/// A GenICam camera opened through aravis.
pub struct AravisCamera {
    info: CameraInfo,
    cam: aravis::Camera,
    profile: CameraProfile,
    stream: Option<aravis::Stream>,
    n_buffers: usize,
    streaming_settings: Option<AppliedSettings>,
    exposure_line: Option<String>,
    gaps: GapFiller,
    control_lost: Arc<AtomicBool>,
}

// SAFETY: aravis objects are GObjects with atomic reference counts; libaravis allows
// a camera and its stream to be used from any thread as long as calls are not made
// concurrently. `AravisCamera` is `Send` but not `Sync`, and all methods take
// `&mut self` or only read immutable identity data, so one thread at a time uses it.
unsafe impl Send for AravisCamera {}

impl AravisCamera {
    /// Open a camera by aravis device id (e.g. `Fake_1`, `Basler-21234567`), IP
    /// address, or serial number.
    pub fn open(id: &str, options: &AravisOptions) -> Result<Self, CameraError> {
        if is_fake_id(id) {
            enable_fake_interface()?;
        }
        let (cam, listed) = {
            let _g = lock();
            let devices = discover_locked();
            let listed = devices.iter().find(|d| d.id == id || d.address.as_deref() == Some(id) || d.serial.as_deref() == Some(id)).cloned();
            let is_address = id.parse::<std::net::IpAddr>().is_ok();
            if listed.is_none() && !is_address {
                return Err(CameraError::NotFound { backend: "aravis".into(), id: id.into(), available: devices.iter().map(|d| d.id.clone()).collect() });
            }
            let open_id = listed.as_ref().map(|d| d.id.clone()).unwrap_or_else(|| id.to_string());
            match aravis::Camera::new(Some(&open_id)) {
                Ok(c) => (c, listed),
                Err(e) => {
                    tracing::warn!(id, error = %e, "aravis could not open camera");
                    return Err(CameraError::NotFound {
                        backend: "aravis".into(),
                        id: format!("{id} ({})", e.message()),
                        available: devices.iter().map(|d| d.id.clone()).collect(),
                    });
                }
            }
        };
        cam.set_range_check_policy(RangeCheckPolicy::Enable);
        cam.set_access_check_policy(AccessCheckPolicy::Enable);
        let vendor = cam.vendor_name().map(|s| s.to_string()).ok();
        let model = cam.model_name().map(|s| s.to_string()).ok();
        let info = CameraInfo {
            backend: "aravis".into(),
            id: listed.as_ref().map(|d| d.id.clone()).unwrap_or_else(|| id.to_string()),
            vendor: vendor.clone(),
            model: model.clone(),
            serial: cam.device_serial_number().map(|s| s.to_string()).ok(),
            address: listed.as_ref().and_then(|d| d.address.clone()).or_else(|| Some(id.to_string())),
            protocol: listed.as_ref().and_then(|d| d.protocol.clone()),
        };
        let profile = options.profile.clone().unwrap_or_else(|| CameraProfile::for_device(vendor.as_deref().unwrap_or(""), model.as_deref().unwrap_or("")));
        let control_lost = Arc::new(AtomicBool::new(false));
        if let Some(dev) = cam.device() {
            let flag = control_lost.clone();
            dev.connect_control_lost(move |_| flag.store(true, Ordering::SeqCst));
        }
        let mut me = AravisCamera {
            info,
            cam,
            profile,
            stream: None,
            n_buffers: options.n_buffers.unwrap_or(8).max(2),
            streaming_settings: None,
            exposure_line: None,
            gaps: GapFiller::new(),
            control_lost,
        };
        me.check_profile()?;
        tracing::info!(camera = %me.info.spec(), profile = %me.profile.name, vendor = ?me.info.vendor, model = ?me.info.model, "opened aravis camera");
        Ok(me)
    }

    pub fn profile(&self) -> &CameraProfile {
        &self.profile
    }

    /// The underlying aravis camera, for features rollcam does not wrap.
    pub fn raw(&self) -> &aravis::Camera {
        &self.cam
    }

    fn name(&self) -> String {
        self.info.id.clone()
    }

    fn has(&self, feature: &str) -> bool {
        self.cam.is_feature_available(feature).unwrap_or(false)
    }

    fn dev_err(&self, context: impl Into<String>) -> impl FnOnce(glib::Error) -> CameraError {
        let camera = self.name();
        let context = context.into();
        move |e| CameraError::Device { camera, context, message: e.message().to_string() }
    }

    fn missing(&self, feature: &str, setting: &str) -> CameraError {
        CameraError::MissingFeature { camera: self.name(), feature: feature.into(), setting: setting.into(), profile: self.profile.name.clone() }
    }

    /// Required features must exist; optional ones only warn.
    fn check_profile(&mut self) -> Result<(), CameraError> {
        let p = self.profile.clone();
        let mut refs: Vec<(&str, &str, bool)> = vec![
            (p.exposure.feature.as_str(), "exposure_us", p.exposure.optional),
            (p.pixel_format.feature.as_str(), "pixel_format", p.pixel_format.optional),
            (p.trigger.mode.as_str(), "trigger", false),
        ];
        if let Some(l) = &p.line_time {
            refs.push((l.feature.as_str(), "line_time_us", l.optional));
        }
        if let Some(s) = &p.shutter {
            refs.push((s.feature.as_str(), "shutter", s.optional));
        }
        for (f, setting) in [(&p.frame_rate, "frame_rate_hz"), (&p.binning_horizontal, "binning"), (&p.binning_vertical, "binning")] {
            if let Some(f) = f {
                refs.push((f.feature.as_str(), setting, f.optional));
            }
        }
        for (feature, setting, optional) in refs {
            if !self.has(feature) {
                if optional {
                    tracing::warn!(camera = %self.name(), feature, setting, profile = %p.name, "feature not available; setting will be skipped");
                } else {
                    return Err(self.missing(feature, setting));
                }
            }
        }
        Ok(())
    }

    fn feature_for<'a>(&self, r: Option<&'a FeatureRef>, setting: &str, fallback: &str) -> Result<&'a str, CameraError> {
        match r {
            Some(r) if self.has(&r.feature) => Ok(r.feature.as_str()),
            Some(r) => Err(self.missing(&r.feature, setting)),
            None => Err(self.missing(fallback, setting)),
        }
    }

    fn set_float_checked(&self, feature: &str, value: f64, unit: &str) -> Result<(), CameraError> {
        let bounds = self.cam.float_bounds(feature).map_err(self.dev_err(format!("reading bounds of {feature}")))?;
        check_range(&self.name(), feature, value, bounds, unit)?;
        self.cam.set_float(feature, value).map_err(self.dev_err(format!("setting {feature} = {value} {unit}")))
    }

    fn set_int_checked(&self, feature: &str, value: i64, unit: &str) -> Result<(), CameraError> {
        let (min, max) = self.cam.integer_bounds(feature).map_err(self.dev_err(format!("reading bounds of {feature}")))?;
        check_range(&self.name(), feature, value as f64, (min as f64, max as f64), unit)?;
        self.cam.set_integer(feature, value).map_err(self.dev_err(format!("setting {feature} = {value}")))
    }

    fn enum_entries(&self, feature: &str) -> Result<Vec<String>, CameraError> {
        self.cam
            .dup_available_enumerations_as_strings(feature)
            .map(|v| v.into_iter().map(|s| s.to_string()).collect())
            .map_err(self.dev_err(format!("listing entries of {feature}")))
    }

    fn set_enum_checked(&self, feature: &str, entry: &str, setting: &str) -> Result<(), CameraError> {
        if !self.has(feature) {
            return Err(self.missing(feature, setting));
        }
        let entries = self.enum_entries(feature)?;
        if !entries.iter().any(|e| e == entry) {
            return Err(CameraError::Unsupported {
                camera: self.name(),
                setting: format!("{setting} ({feature})"),
                value: entry.into(),
                expected: format!("one of {}", entries.join(", ")),
            });
        }
        self.cam.set_string(feature, entry).map_err(self.dev_err(format!("setting {feature} = {entry}")))
    }

    fn select_trigger(&self) -> Result<(), CameraError> {
        let t = &self.profile.trigger;
        if let Some(sel) = &t.selector {
            if self.has(sel) {
                self.set_enum_checked(sel, &t.selector_value, "trigger")?;
            }
        }
        Ok(())
    }

    fn binning_now(&self) -> Binning {
        let read = |r: &Option<FeatureRef>| {
            r.as_ref().filter(|r| self.has(&r.feature)).and_then(|r| self.cam.integer(&r.feature).ok()).map(|v| v.max(1) as u32).unwrap_or(1)
        };
        Binning { horizontal: read(&self.profile.binning_horizontal), vertical: read(&self.profile.binning_vertical) }
    }

    fn sensor_size(&self) -> Result<(u32, u32), CameraError> {
        let (w, h) = self.cam.sensor_size().map_err(self.dev_err("reading SensorWidth/SensorHeight"))?;
        Ok((w as u32, h as u32))
    }

    /// Still answering? Used after a frame timeout to tell a stall from an unplug.
    fn device_alive(&self) -> Result<(), String> {
        if self.control_lost.load(Ordering::SeqCst) {
            return Err("aravis reported control lost".into());
        }
        if self.info.protocol.as_deref().is_some_and(|p| p.to_ascii_lowercase().contains("usb")) {
            let devices = discover();
            if !devices.iter().any(|d| d.id == self.info.id) {
                return Err("device is no longer enumerated on USB".into());
            }
        }
        self.cam.sensor_size().map(|_| ()).map_err(|e| format!("device stopped answering register reads: {}", e.message()))
    }
}

impl Camera for AravisCamera {
    fn info(&self) -> &CameraInfo {
        &self.info
    }

    fn geometry(&mut self) -> Result<SensorGeometry, CameraError> {
        let (width, height) = self.sensor_size()?;
        let max_bit_depth = self
            .enum_entries(&self.profile.pixel_format.feature)
            .unwrap_or_default()
            .iter()
            .filter_map(|e| PixelFormat::from_genicam_name(e))
            .map(|p| p.bit_depth())
            .max()
            .unwrap_or(8);
        Ok(SensorGeometry { width, height, max_bit_depth })
    }

    fn capabilities(&mut self) -> Result<Capabilities, CameraError> {
        let p = self.profile.clone();
        let exposure_range_us = self.cam.float_bounds(&p.exposure.feature).ok();
        let line_time_range_us = p.line_time.as_ref().filter(|l| self.has(&l.feature)).and_then(|l| {
            let b = self.cam.float_bounds(&l.feature).ok()?;
            Some(match l.unit {
                LineTimeUnit::Us => b,
                LineTimeUnit::Hz => (1e6 / b.1, 1e6 / b.0),
            })
        });
        let frame_rate_range_hz = p.frame_rate.as_ref().filter(|f| self.has(&f.feature)).and_then(|f| self.cam.float_bounds(&f.feature).ok());
        let shutter_modes = match &p.shutter {
            Some(s) if self.has(&s.feature) => self.enum_entries(&s.feature)?.iter().filter_map(|e| s.mode_of(e)).collect(),
            _ => Vec::new(),
        };
        let pixel_formats = self.enum_entries(&p.pixel_format.feature)?.iter().filter_map(|e| PixelFormat::from_genicam_name(e)).collect();
        let max_of = |r: &Option<FeatureRef>| {
            r.as_ref().filter(|r| self.has(&r.feature)).and_then(|r| self.cam.integer_bounds(&r.feature).ok()).map(|b| b.1 as u32).unwrap_or(1)
        };
        let max_binning = Binning { horizontal: max_of(&p.binning_horizontal), vertical: max_of(&p.binning_vertical) };
        let software_trigger =
            self.has(&p.trigger.software) && self.enum_entries(&p.trigger.source).map(|e| e.contains(&p.trigger.software_source)).unwrap_or(false);
        let hardware_trigger_lines = self.enum_entries(&p.trigger.source).unwrap_or_default().into_iter().filter(|e| e.starts_with("Line")).collect();
        Ok(Capabilities {
            exposure_range_us,
            line_time_range_us,
            frame_rate_range_hz,
            shutter_modes,
            pixel_formats,
            max_binning,
            software_trigger,
            hardware_trigger_lines,
        })
    }

    fn configure(&mut self, req: &CameraSettings) -> Result<AppliedSettings, CameraError> {
        if self.stream.is_some() {
            return Err(CameraError::State { camera: self.name(), message: "cannot configure while streaming".into() });
        }
        let p = self.profile.clone();
        if let Some(pf) = req.pixel_format {
            self.set_enum_checked(&p.pixel_format.feature, pf.genicam_name(), "pixel_format")?;
        }
        if let Some(b) = req.binning {
            let fh = self.feature_for(p.binning_horizontal.as_ref(), "binning", "BinningHorizontal")?;
            self.set_int_checked(fh, b.horizontal as i64, "px")?;
            let fv = self.feature_for(p.binning_vertical.as_ref(), "binning", "BinningVertical")?;
            self.set_int_checked(fv, b.vertical as i64, "px")?;
        }
        if let Some(r) = req.roi {
            let (sw, sh) = self.sensor_size()?;
            let b = self.binning_now();
            if r.width == 0 || r.height == 0 || r.x + r.width > sw || r.y + r.height > sh {
                return Err(CameraError::Unsupported {
                    camera: self.name(),
                    setting: "roi".into(),
                    value: format!("{}x{}+{}+{}", r.width, r.height, r.x, r.y),
                    expected: format!("a non-empty region inside the {sw}x{sh} sensor"),
                });
            }
            if r.width % b.horizontal != 0 || r.height % b.vertical != 0 || r.x % b.horizontal != 0 || r.y % b.vertical != 0 {
                return Err(CameraError::Unsupported {
                    camera: self.name(),
                    setting: "roi".into(),
                    value: format!("{}x{}+{}+{}", r.width, r.height, r.x, r.y),
                    expected: format!("multiples of the binning {}x{}", b.horizontal, b.vertical),
                });
            }
            // GenICam Width/Height/Offset are in binned pixels.
            self.cam
                .set_region((r.x / b.horizontal) as i32, (r.y / b.vertical) as i32, (r.width / b.horizontal) as i32, (r.height / b.vertical) as i32)
                .map_err(self.dev_err("setting OffsetX/OffsetY/Width/Height"))?;
        }
        if let Some(mode) = req.shutter {
            let s = p.shutter.as_ref().ok_or_else(|| self.missing("SensorShutterMode", "shutter"))?;
            let entry = s.entry(mode).ok_or_else(|| CameraError::Unsupported {
                camera: self.name(),
                setting: "shutter".into(),
                value: mode.to_string(),
                expected: format!(
                    "one of {} (profile {})",
                    CameraShutter::ALL.iter().filter(|m| s.entry(**m).is_some()).map(|m| m.as_str()).collect::<Vec<_>>().join(", "),
                    p.name
                ),
            })?;
            self.set_enum_checked(&s.feature, entry, "shutter")?;
        }
        if let Some(lt) = req.line_time_us {
            let l = p.line_time.as_ref().ok_or_else(|| self.missing("LineTime", "line_time_us"))?;
            if !self.has(&l.feature) {
                return Err(self.missing(&l.feature, "line_time_us"));
            }
            match l.unit {
                LineTimeUnit::Us => self.set_float_checked(&l.feature, lt, "us")?,
                LineTimeUnit::Hz => {
                    let (rmin, rmax) = self.cam.float_bounds(&l.feature).map_err(self.dev_err(format!("reading bounds of {}", l.feature)))?;
                    check_range(&self.name(), &l.feature, lt, (1e6 / rmax, 1e6 / rmin), "us")?;
                    self.cam.set_float(&l.feature, 1e6 / lt).map_err(self.dev_err(format!("setting {}", l.feature)))?;
                }
            }
        }
        if let Some(fr) = req.frame_rate_hz {
            if let Some(en) = p.frame_rate_enable.as_ref().filter(|e| self.has(&e.feature)) {
                self.cam.set_boolean(&en.feature, true).map_err(self.dev_err(format!("setting {} = true", en.feature)))?;
            }
            let f = self.feature_for(p.frame_rate.as_ref(), "frame_rate_hz", "AcquisitionFrameRate")?;
            self.set_float_checked(f, fr, "Hz")?;
        }
        if let Some(e) = req.exposure_us {
            let f = self.feature_for(Some(&p.exposure), "exposure_us", "ExposureTime")?;
            self.set_float_checked(f, e, "us")?;
        }
        if let Some(t) = &req.trigger {
            let tr = &p.trigger;
            self.select_trigger()?;
            match t {
                Trigger::FreeRun => self.set_enum_checked(&tr.mode, &tr.mode_off, "trigger")?,
                Trigger::Software => {
                    self.set_enum_checked(&tr.mode, &tr.mode_on, "trigger")?;
                    self.set_enum_checked(&tr.source, &tr.software_source, "trigger source")?;
                }
                Trigger::Hardware { line, edge } => {
                    self.set_enum_checked(&tr.mode, &tr.mode_on, "trigger")?;
                    self.set_enum_checked(&tr.source, line, "trigger source")?;
                    let act = tr.activation.as_ref().ok_or_else(|| self.missing("TriggerActivation", "trigger edge"))?;
                    let entry = match edge {
                        Edge::Rising => &tr.rising,
                        Edge::Falling => &tr.falling,
                        Edge::Any => &tr.any,
                    };
                    self.set_enum_checked(act, entry, "trigger edge")?;
                }
            }
        }
        if let Some(line) = &req.exposure_output_line {
            let o = p.exposure_output.as_ref().ok_or_else(|| self.missing("LineSource", "exposure_output_line"))?;
            self.set_enum_checked(&o.line_selector, line, "exposure_output_line")?;
            if let (Some(mode), Some(value)) = (&o.line_mode, &o.line_mode_value) {
                self.set_enum_checked(mode, value, "exposure_output_line")?;
            }
            self.set_enum_checked(&o.line_source, &o.source_value, "exposure_output_line")?;
            self.exposure_line = Some(line.clone());
        }
        let applied = self.applied_settings()?;
        tracing::info!(camera = %self.name(), ?applied, "configured");
        Ok(applied)
    }

    fn applied_settings(&mut self) -> Result<AppliedSettings, CameraError> {
        let p = self.profile.clone();
        let exposure_us = self.cam.float(&p.exposure.feature).map_err(self.dev_err(format!("reading {}", p.exposure.feature)))?;
        let line_time_us = match &p.line_time {
            Some(l) if self.has(&l.feature) => {
                let v = self.cam.float(&l.feature).map_err(self.dev_err(format!("reading {}", l.feature)))?;
                Some(match l.unit {
                    LineTimeUnit::Us => v,
                    LineTimeUnit::Hz => 1e6 / v,
                })
            }
            _ => None,
        };
        let frame_rate_hz = p.frame_rate.as_ref().filter(|f| self.has(&f.feature)).and_then(|f| self.cam.float(&f.feature).ok());
        let shutter = match &p.shutter {
            Some(s) if self.has(&s.feature) => {
                let entry = self.cam.string(&s.feature).map_err(self.dev_err(format!("reading {}", s.feature)))?;
                let mode = s.mode_of(&entry);
                if mode.is_none() {
                    tracing::warn!(camera = %self.name(), feature = %s.feature, entry = %entry, "shutter entry not mapped by profile");
                }
                mode
            }
            _ => None,
        };
        let binning = self.binning_now();
        let (x, y, w, h) = self.cam.region().map_err(self.dev_err("reading OffsetX/OffsetY/Width/Height"))?;
        let roi =
            Roi { x: x as u32 * binning.horizontal, y: y as u32 * binning.vertical, width: w as u32 * binning.horizontal, height: h as u32 * binning.vertical };
        let pf_name = self.cam.string(&p.pixel_format.feature).map_err(self.dev_err(format!("reading {}", p.pixel_format.feature)))?;
        let pixel_format = PixelFormat::from_genicam_name(&pf_name).ok_or_else(|| CameraError::Unsupported {
            camera: self.name(),
            setting: format!("pixel_format ({})", p.pixel_format.feature),
            value: pf_name.to_string(),
            expected: "Mono8, Mono10, Mono12, Mono14 or Mono16".into(),
        })?;
        let tr = &p.trigger;
        self.select_trigger()?;
        let mode = self.cam.string(&tr.mode).map_err(self.dev_err(format!("reading {}", tr.mode)))?;
        let trigger = if mode.as_str() != tr.mode_on {
            Trigger::FreeRun
        } else {
            let source = self.cam.string(&tr.source).map_err(self.dev_err(format!("reading {}", tr.source)))?;
            if source.as_str() == tr.software_source {
                Trigger::Software
            } else {
                let edge = match &tr.activation {
                    Some(a) if self.has(a) => {
                        let v = self.cam.string(a).map_err(self.dev_err(format!("reading {a}")))?;
                        if v.as_str() == tr.falling {
                            Edge::Falling
                        } else if v.as_str() == tr.any {
                            Edge::Any
                        } else {
                            Edge::Rising
                        }
                    }
                    _ => Edge::Rising,
                };
                Trigger::Hardware { line: source.to_string(), edge }
            }
        };
        let exposure_output_line = match (&p.exposure_output, &self.exposure_line) {
            (Some(o), Some(line)) => {
                self.cam.set_string(&o.line_selector, line).map_err(self.dev_err(format!("setting {} = {line}", o.line_selector)))?;
                let src = self.cam.string(&o.line_source).map_err(self.dev_err(format!("reading {}", o.line_source)))?;
                (src.as_str() == o.source_value).then(|| line.clone())
            }
            _ => None,
        };
        Ok(AppliedSettings { exposure_us, line_time_us, frame_rate_hz, shutter, roi, binning, pixel_format, trigger, exposure_output_line })
    }

    fn start(&mut self) -> Result<(), CameraError> {
        if self.stream.is_some() {
            return Ok(());
        }
        let settings = self.applied_settings()?;
        let payload = self.cam.payload().map_err(self.dev_err("reading PayloadSize"))?;
        let stream = self.cam.create_stream().map_err(self.dev_err("creating stream"))?;
        for _ in 0..self.n_buffers {
            stream.push_buffer(aravis::Buffer::new_allocate(payload as usize));
        }
        self.cam.set_acquisition_mode(aravis::AcquisitionMode::Continuous).map_err(self.dev_err("setting AcquisitionMode = Continuous"))?;
        self.cam.start_acquisition().map_err(self.dev_err("AcquisitionStart"))?;
        self.stream = Some(stream);
        self.streaming_settings = Some(settings);
        self.gaps.reset();
        tracing::info!(camera = %self.name(), payload, "acquisition started");
        Ok(())
    }

    fn software_trigger(&mut self) -> Result<(), CameraError> {
        let cmd = self.profile.trigger.software.clone();
        if !self.has(&cmd) {
            return Err(self.missing(&cmd, "software trigger"));
        }
        self.cam.execute_command(&cmd).map_err(self.dev_err(format!("executing {cmd}")))
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        if let Some(f) = self.gaps.pop() {
            return Ok(f);
        }
        let stream = self.stream.as_ref().ok_or_else(|| CameraError::State { camera: self.name(), message: "next_frame called before start".into() })?;
        let Some(buffer) = stream.timeout_pop_buffer(timeout.as_micros() as u64) else {
            if let Err(detail) = self.device_alive() {
                return Err(CameraError::Disconnected { camera: self.name(), detail });
            }
            return Err(CameraError::Timeout { camera: self.name(), timeout_ms: timeout.as_millis() as u64 });
        };
        let settings = self.streaming_settings.clone().expect("set by start");
        let status = buffer.status();
        // A failed buffer may carry no image header: fall back to the configured size.
        let (cfg_w, cfg_h) = settings.image_size();
        let width = if buffer.image_width() > 0 { buffer.image_width() as u32 } else { cfg_w };
        let height = if buffer.image_height() > 0 { buffer.image_height() as u32 } else { cfg_h };
        let (pixels, short) = if status == BufferStatus::Success || status == BufferStatus::MissingPackets {
            bytes_to_u16(settings.pixel_format, &buffer.image_data(), width, height)
        } else {
            (Vec::new(), true)
        };
        let frame_status = if status == BufferStatus::Success && !short {
            FrameStatus::Complete
        } else {
            tracing::warn!(camera = %self.name(), ?status, frame_id = buffer.frame_id(), "incomplete buffer");
            FrameStatus::Incomplete
        };
        let sys_ts = buffer.system_timestamp();
        let meta = FrameMeta {
            camera: self.info.spec(),
            frame_id: buffer.frame_id(),
            sequence: 0,
            device_timestamp_ns: buffer.timestamp(),
            host_timestamp_ns: if sys_ts > 0 { sys_ts } else { host_now_ns() },
            status: frame_status,
            width,
            height,
            bit_depth: settings.pixel_format.bit_depth(),
            valid_pixels: pixels.len() as u64,
            settings,
        };
        stream.push_buffer(buffer);
        Ok(self.gaps.push(Frame { meta, pixels }))
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        if let Some(stream) = self.stream.take() {
            let r = self.cam.stop_acquisition().map_err(self.dev_err("AcquisitionStop"));
            drop(stream);
            self.streaming_settings = None;
            tracing::info!(camera = %self.name(), "acquisition stopped");
            r?;
        }
        Ok(())
    }
}

impl Drop for AravisCamera {
    fn drop(&mut self) {
        if self.stream.is_some() {
            let _ = self.stop();
        }
    }
}

/// Start an aravis GigE Vision fake camera on `interface` (e.g. `127.0.0.1`) using
/// rollcam's GenICam XML; it answers as a real GigE camera at that address and, unlike
/// the in-library Fake interface, honours `TriggerSoftware`. Keep the returned object
/// alive while it is used. For tests and bench dry runs.
pub fn start_gv_fake_camera(interface: &str, serial: &str) -> Result<aravis::GvFakeCamera, CameraError> {
    let xml = fake_camera_xml_path()?;
    let gv = aravis::GvFakeCamera::new_full(Some(interface), Some(serial), Some(&xml.to_string_lossy()));
    if !gv.is_running() {
        return Err(CameraError::Device {
            camera: format!("GvFake {serial}"),
            context: format!("starting GigE Vision fake camera on {interface}"),
            message: "not listening on the GVCP port (is port 3956 in use?)".into(),
        });
    }
    Ok(gv)
}
