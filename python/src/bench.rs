//! The bench from Python: `rollcam.Camera` (any camera `rollcam capture` opens:
//! `sim:<scene>`, `replay:<folder>`, `aravis:<id>` in a build with GenICam support),
//! `rollcam.LedController` (the commands of `rollcam led`) and `rollcam.LedEmulator`
//! (the software controller of `rollcam led emulate`, on a pseudo-terminal).
//!
//! Errors: a setting out of range or not supported, a bad spec or channel
//! configuration raise `ValueError`; a camera or port not found `FileNotFoundError`;
//! no frame or no reply in time `TimeoutError`; the end of a replayed capture
//! `EOFError`; permission problems `PermissionError`; other device and link failures
//! `OSError`. Messages are the command-line tool's.

use crate::{to_python, PyTiming};
use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::{PyEOFError, PyFileNotFoundError, PyOSError, PyPermissionError, PyRuntimeError, PyTimeoutError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use rollcam::lab::camera::{open_camera, CameraOptions, CameraTarget, OpenCamera};
use rollcam::lab::led::{channel_config, guess_port, snapshot};
use rollcam_hw::camera::{Binning, CameraError, CameraSettings, Frame, FrameStatus};
use rollcam_hw::led::{available_ports, LedController, LedError, LinkOptions, LinkedEmulator, TriggerMode};
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Duration;

fn camera_error(e: CameraError) -> PyErr {
    let m = e.to_string();
    match e {
        CameraError::OutOfRange { .. } | CameraError::Unsupported { .. } | CameraError::MissingFeature { .. } | CameraError::Spec { .. } => {
            PyValueError::new_err(m)
        }
        CameraError::NotFound { .. } => PyFileNotFoundError::new_err(m),
        CameraError::Timeout { .. } => PyTimeoutError::new_err(m),
        CameraError::EndOfStream { .. } => PyEOFError::new_err(m),
        CameraError::State { .. } | CameraError::Render { .. } => PyRuntimeError::new_err(m),
        _ => PyOSError::new_err(m),
    }
}

/// An error of opening a camera: the camera's own kind when it is one, else a
/// `ValueError` (an unknown simulated scene) with the whole chain of causes.
fn open_error(e: anyhow::Error) -> PyErr {
    let chain = format!("{e:#}");
    match e.downcast::<CameraError>() {
        Ok(c) => {
            let kind = camera_error(c);
            Python::with_gil(|py| PyErr::from_type(kind.get_type(py), chain))
        }
        Err(_) => PyValueError::new_err(chain),
    }
}

fn led_error(e: LedError) -> PyErr {
    let m = e.to_string();
    match e {
        LedError::PortNotFound { .. } => PyFileNotFoundError::new_err(m),
        LedError::PermissionDenied { .. } => PyPermissionError::new_err(m),
        LedError::Silent { .. } => PyTimeoutError::new_err(m),
        LedError::Nak { .. } | LedError::Config { .. } => PyValueError::new_err(m),
        _ => PyOSError::new_err(m),
    }
}

fn parse<T: std::str::FromStr<Err = String>>(what: &str, s: &str) -> PyResult<T> {
    s.parse::<T>().map_err(|e| PyValueError::new_err(format!("{what}: {e}")))
}

/// One frame from a camera.
#[pyclass(module = "rollcam", name = "Frame", frozen, get_all)]
struct PyFrame {
    /// The samples: (height, width) uint16 for a complete frame; for an incomplete
    /// or dropped one, the samples that arrived, flat (empty for a dropped frame).
    pixels: Py<PyAny>,
    /// complete, incomplete or dropped.
    status: String,
    /// Frame ids, timestamps, size, bit depth and the settings the camera applied.
    meta: Py<PyAny>,
}

#[pymethods]
impl PyFrame {
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let shape = self.pixels.bind(py).getattr("shape")?.repr()?.to_string();
        Ok(format!("Frame(status={:?}, pixels {shape})", self.status))
    }
}

fn frame_object(py: Python<'_>, f: Frame) -> PyResult<PyFrame> {
    let (w, h) = (f.meta.width as usize, f.meta.height as usize);
    let status = match f.meta.status {
        FrameStatus::Complete => "complete",
        FrameStatus::Incomplete => "incomplete",
        FrameStatus::Dropped => "dropped",
    };
    let meta = to_python(py, &f.meta)?;
    let pixels = if f.meta.status == FrameStatus::Complete && f.pixels.len() == w * h {
        ndarray::Array2::from_shape_vec((h, w), f.pixels).expect("height x width samples").into_pyarray(py).into_any()
    } else {
        PyArray1::from_vec(py, f.pixels).into_any()
    };
    Ok(PyFrame { pixels: pixels.unbind(), status: status.into(), meta: meta.unbind() })
}

struct Open {
    camera: OpenCamera,
    streaming: bool,
}

/// A camera, as `rollcam capture --camera SPEC` opens it: `Camera.open("sim:led-array")`,
/// `"sim:moving-disc"`, `"replay:/path/to/capture"`, `"aravis:Fake_1"` (GenICam, in a
/// build with the `aravis` feature). Use as a context manager, or call close().
#[pyclass(module = "rollcam", name = "Camera", frozen)]
pub(crate) struct PyCamera {
    spec: String,
    open: Mutex<Option<Open>>,
}

impl PyCamera {
    fn with<R>(&self, py: Python<'_>, f: impl FnOnce(&mut Open) -> Result<R, CameraError> + Send) -> PyResult<R>
    where
        R: Send,
    {
        py.allow_threads(|| {
            let mut guard = self.open.lock().map_err(|_| PyRuntimeError::new_err(format!("camera {}: a previous call panicked", self.spec)))?;
            let open = guard.as_mut().ok_or_else(|| PyValueError::new_err(format!("camera {} is closed", self.spec)))?;
            f(open).map_err(camera_error)
        })
    }
}

#[pymethods]
impl PyCamera {
    /// Open the camera `spec` names (backend:id).
    #[staticmethod]
    fn open(py: Python<'_>, spec: &str) -> PyResult<PyCamera> {
        let target = CameraTarget::parse(spec).map_err(camera_error)?;
        let camera = py.allow_threads(|| open_camera(&target, CameraOptions::default())).map_err(open_error)?;
        Ok(PyCamera { spec: spec.to_string(), open: Mutex::new(Some(Open { camera, streaming: false })) })
    }

    /// The camera's spec as opened.
    #[getter]
    fn spec(&self) -> &str {
        &self.spec
    }

    /// Identity: backend, id, vendor, model, serial, address, protocol.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let info = self.with(py, |o| Ok(o.camera.camera().info().clone()))?;
        to_python(py, &info)
    }

    /// Full sensor size and depth: width, height, max_bit_depth.
    fn geometry<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let g = self.with(py, |o| o.camera.camera().geometry())?;
        to_python(py, &g)
    }

    /// Ranges and choices the device reports.
    fn capabilities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let c = self.with(py, |o| o.camera.camera().capabilities())?;
        to_python(py, &c)
    }

    /// Apply settings (those given; the others keep the device's values), as `rollcam
    /// capture`'s flags: exposure_us, line_time_us, frame_rate_hz, shutter (global,
    /// rolling, dual), roi ("x,y,width,height" or a 4-tuple), binning (a factor for
    /// both directions), pixel_format (Mono8 ... Mono16), trigger (free-run, software,
    /// hardware:<line>[:edge]), exposure_output_line. Returns the settings the device
    /// reports back. Refused while streaming (call stop() first).
    #[pyo3(signature = (*, exposure_us = None, line_time_us = None, frame_rate_hz = None, shutter = None, roi = None, binning = None,
        pixel_format = None, trigger = None, exposure_output_line = None))]
    #[allow(clippy::too_many_arguments)]
    fn configure<'py>(
        &self,
        py: Python<'py>,
        exposure_us: Option<f64>,
        line_time_us: Option<f64>,
        frame_rate_hz: Option<f64>,
        shutter: Option<&str>,
        roi: Option<&Bound<'py, PyAny>>,
        binning: Option<u32>,
        pixel_format: Option<&str>,
        trigger: Option<&str>,
        exposure_output_line: Option<String>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let roi = match roi {
            None => None,
            Some(r) => Some(match r.extract::<String>() {
                Ok(s) => parse("roi", &s)?,
                Err(_) => {
                    let (x, y, width, height): (u32, u32, u32, u32) =
                        r.extract().map_err(|_| PyValueError::new_err("roi: expected (x, y, width, height) or \"x,y,width,height\""))?;
                    rollcam_hw::camera::Roi { x, y, width, height }
                }
            }),
        };
        let settings = CameraSettings {
            exposure_us,
            line_time_us,
            frame_rate_hz,
            shutter: shutter.map(|s| parse("shutter", s)).transpose()?,
            roi,
            binning: binning.map(|b| Binning { horizontal: b, vertical: b }),
            pixel_format: pixel_format.map(|s| parse("pixel_format", s)).transpose()?,
            trigger: trigger.map(|s| parse("trigger", s)).transpose()?,
            exposure_output_line,
        };
        let applied = self.with(py, |o| o.camera.camera().configure(&settings))?;
        to_python(py, &applied)
    }

    /// The settings the device reports now.
    fn applied_settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let a = self.with(py, |o| o.camera.camera().applied_settings())?;
        to_python(py, &a)
    }

    /// Start acquisition (grab() starts it when needed).
    fn start(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, |o| {
            if !o.streaming {
                o.camera.camera().start()?;
                o.streaming = true;
            }
            Ok(())
        })
    }

    /// Stop acquisition. Idempotent.
    fn stop(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, |o| {
            o.streaming = false;
            o.camera.camera().stop()
        })
    }

    /// Fire one software trigger (trigger mode software).
    fn software_trigger(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, |o| o.camera.camera().software_trigger())
    }

    /// The next frame, waiting up to timeout_ms (starting acquisition first if it is
    /// not running). Raises TimeoutError when none comes, EOFError at the end of a
    /// replayed capture.
    #[pyo3(signature = (timeout_ms = 5000))]
    fn grab(&self, py: Python<'_>, timeout_ms: u64) -> PyResult<PyFrame> {
        let f = self.with(py, |o| {
            if !o.streaming {
                o.camera.camera().start()?;
                o.streaming = true;
            }
            o.camera.camera().next_frame(Duration::from_millis(timeout_ms))
        })?;
        frame_object(py, f)
    }

    /// Iterate over the next `count` frames (every frame until the stream ends when
    /// None), each waited for up to timeout_ms.
    #[pyo3(signature = (count = None, timeout_ms = 5000))]
    fn frames(slf: Py<Self>, count: Option<u64>, timeout_ms: u64) -> FrameIter {
        FrameIter { camera: slf, left: count, timeout_ms }
    }

    /// For a simulated camera, its calibration with the current settings: the PSF as
    /// recorded (rows, cols float32 counts, dark level included), the Timing of its
    /// frames and the capture description as a dict, so that a grabbed frame can be
    /// reconstructed. None for other cameras (their PSF is measured on the bench).
    fn calibration<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyTuple>>> {
        let got = py.allow_threads(|| {
            let mut guard = self.open.lock().expect("camera lock");
            guard.as_mut().map(|o| o.camera.calibration())
        });
        let Some(Some(result)) = got else {
            return match got {
                None => Err(PyValueError::new_err(format!("camera {} is closed", self.spec))),
                Some(_) => Ok(None),
            };
        };
        let (psf, cfg) = result.map_err(|e| PyRuntimeError::new_err(format!("{e:#}")))?;
        let psf = psf.index_axis_move(ndarray::Axis(2), 0).into_dyn().into_pyarray(py).into_any();
        let timing = Py::new(py, PyTiming::of_config(&cfg))?.into_any();
        Ok(Some(PyTuple::new(py, [psf, timing.into_bound(py), to_python(py, &cfg)?])?))
    }

    /// Stop acquisition and release the camera.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        let taken = py.allow_threads(|| self.open.lock().map(|mut g| g.take()).ok().flatten());
        if let Some(mut o) = taken {
            py.allow_threads(|| o.camera.camera().stop()).map_err(camera_error)?;
        }
        Ok(())
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    fn __exit__(&self, py: Python<'_>, _t: Option<&Bound<'_, PyAny>>, _v: Option<&Bound<'_, PyAny>>, _tb: Option<&Bound<'_, PyAny>>) -> PyResult<bool> {
        self.close(py)?;
        Ok(false)
    }

    fn __repr__(&self) -> String {
        format!("Camera.open({:?})", self.spec)
    }
}

/// Frames of a camera, one grab() each (from Camera.frames()).
#[pyclass(module = "rollcam")]
struct FrameIter {
    camera: Py<PyCamera>,
    left: Option<u64>,
    timeout_ms: u64,
}

#[pymethods]
impl FrameIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<PyFrame>> {
        if self.left == Some(0) {
            return Ok(None);
        }
        match self.camera.get().grab(py, self.timeout_ms) {
            Ok(f) => {
                self.left = self.left.map(|n| n - 1);
                Ok(Some(f))
            }
            Err(e) if self.left.is_none() && e.is_instance_of::<PyEOFError>(py) => Ok(None),
            Err(e) => Err(e),
        }
    }
}

fn trigger_mode(s: &str) -> PyResult<TriggerMode> {
    match s {
        "sw" | "software" => Ok(TriggerMode::Software),
        "rise" | "rising" => Ok(TriggerMode::Rising),
        "fall" | "falling" => Ok(TriggerMode::Falling),
        other => Err(PyValueError::new_err(format!("trigger '{other}': expected sw, rise or fall"))),
    }
}

/// The LED pulse controller on a serial port, with the commands of `rollcam led`.
/// port None: the only USB serial port that looks like an Arduino.
#[pyclass(module = "rollcam", name = "LedController", frozen)]
pub(crate) struct PyLedController {
    port: String,
    ctl: Mutex<Option<LedController>>,
}

impl PyLedController {
    fn with<R: Send>(&self, py: Python<'_>, f: impl FnOnce(&mut LedController) -> Result<R, LedError> + Send) -> PyResult<R> {
        py.allow_threads(|| {
            let mut guard = self.ctl.lock().map_err(|_| PyRuntimeError::new_err(format!("{}: a previous call panicked", self.port)))?;
            let ctl = guard.as_mut().ok_or_else(|| PyValueError::new_err(format!("LED controller on {} is closed", self.port)))?;
            f(ctl).map_err(led_error)
        })
    }
}

#[pymethods]
impl PyLedController {
    #[new]
    #[pyo3(signature = (port = None, *, baud = rollcam_hw::led::DEFAULT_BAUD, timeout_ms = 300, retries = 2, ready_ms = 2500))]
    fn new(py: Python<'_>, port: Option<PathBuf>, baud: u32, timeout_ms: u64, retries: u32, ready_ms: u64) -> PyResult<Self> {
        let port = match port {
            Some(p) => p.display().to_string(),
            None => guess_port().map_err(|e| PyFileNotFoundError::new_err(format!("{e:#}")))?,
        };
        let opts = LinkOptions { baud, reply_timeout: Duration::from_millis(timeout_ms), retries, ready_timeout: Duration::from_millis(ready_ms) };
        let ctl = py.allow_threads(|| LedController::open_with(&port, opts)).map_err(led_error)?;
        Ok(PyLedController { port, ctl: Mutex::new(Some(ctl)) })
    }

    #[getter]
    fn port(&self) -> &str {
        &self.port
    }

    /// Who the controller is: name, protocol, firmware, hardware, channels, tick_ns.
    fn identify<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let info = self.with(py, |c| c.identify())?;
        to_python(py, &info)
    }

    /// Configure and enable one channel (0-3): period_us (100 to 10000000), duty
    /// (0 < duty < 1, default 0.5) or width_us (high time), phase_us (delay from the
    /// trigger), count (pulses; None: until stop). Returns the channel as the
    /// controller reports it.
    #[pyo3(signature = (channel, period_us, *, duty = None, width_us = None, phase_us = 0, count = None))]
    fn set<'py>(
        slf: &Bound<'py, Self>,
        channel: u8,
        period_us: u32,
        duty: Option<f64>,
        width_us: Option<u32>,
        phase_us: u32,
        count: Option<u32>,
    ) -> PyResult<Bound<'py, PyAny>> {
        if duty.is_some() && width_us.is_some() {
            return Err(PyValueError::new_err("give duty or width_us, not both"));
        }
        let cfg = channel_config(period_us, duty, width_us, phase_us, count).map_err(|e| PyValueError::new_err(e.to_string()))?;
        let py = slf.py();
        let report = slf.get().with(py, |c| {
            c.configure(channel, cfg)?;
            c.channel(channel)
        })?;
        to_python(py, &report)
    }

    /// Disable one channel.
    fn off(&self, py: Python<'_>, channel: u8) -> PyResult<()> {
        self.with(py, |c| c.disable(channel))
    }

    /// Arm: wait for a software trigger ("sw") or an edge on the trigger input
    /// ("rise", "fall").
    #[pyo3(signature = (trigger = "sw"))]
    fn arm(&self, py: Python<'_>, trigger: &str) -> PyResult<()> {
        let mode = trigger_mode(trigger)?;
        self.with(py, |c| c.arm(mode))
    }

    /// Software trigger (the controller must be armed).
    fn trigger(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, |c| c.trigger())
    }

    /// Stop: outputs low, back to idle (configuration kept).
    fn stop(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, |c| c.stop())
    }

    /// Run state and every channel's configuration: {"status": ..., "channels": [...]}.
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let snap = self.with(py, snapshot)?;
        let d = PyDict::new(py);
        d.set_item("port", &self.port)?;
        d.set_item("status", to_python(py, &snap.status)?)?;
        d.set_item("channels", to_python(py, &snap.channels)?)?;
        Ok(d.into_any())
    }

    /// The synchronisation summary stored in capture metadata, for a trigger mode.
    #[pyo3(signature = (trigger = "rise"))]
    fn sync<'py>(&self, py: Python<'py>, trigger: &str) -> PyResult<Bound<'py, PyAny>> {
        let mode = trigger_mode(trigger)?;
        let s = self.with(py, |c| c.sync_summary(mode))?;
        to_python(py, &s)
    }

    /// Release the port.
    fn close(&self) {
        if let Ok(mut g) = self.ctl.lock() {
            g.take();
        }
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    fn __exit__(&self, _t: Option<&Bound<'_, PyAny>>, _v: Option<&Bound<'_, PyAny>>, _tb: Option<&Bound<'_, PyAny>>) -> bool {
        self.close();
        false
    }

    fn __repr__(&self) -> String {
        format!("LedController({:?})", self.port)
    }
}

/// Serial ports on this machine: path, description, likely_controller.
#[pyfunction]
pub(crate) fn led_ports(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    let ports = available_ports().map_err(|e| PyOSError::new_err(format!("listing serial ports: {e}")))?;
    to_python(py, &ports)
}

/// A software LED controller on a pseudo-terminal, reachable at the symlink `link`
/// (as `rollcam led emulate --link LINK`): open a LedController on `link`. Use as a
/// context manager, or call close() (which removes the link).
#[pyclass(module = "rollcam", name = "LedEmulator", frozen)]
pub(crate) struct PyLedEmulator {
    link: PathBuf,
    linked: Mutex<Option<LinkedEmulator>>,
}

impl PyLedEmulator {
    fn with<R>(&self, f: impl FnOnce(&LinkedEmulator) -> R) -> PyResult<R> {
        let guard = self.linked.lock().map_err(|_| PyRuntimeError::new_err("emulator lock poisoned"))?;
        let linked = guard.as_ref().ok_or_else(|| PyValueError::new_err(format!("emulator on {} is closed", self.link.display())))?;
        Ok(f(linked))
    }
}

#[pymethods]
impl PyLedEmulator {
    #[new]
    fn new(link: PathBuf) -> PyResult<Self> {
        let linked = LinkedEmulator::create(&link, Default::default()).map_err(|e| PyOSError::new_err(e.to_string()))?;
        Ok(PyLedEmulator { link, linked: Mutex::new(Some(linked)) })
    }

    /// The symlink a LedController opens.
    #[getter]
    fn link(&self) -> PathBuf {
        self.link.clone()
    }

    /// The pseudo-terminal the link points to.
    #[getter]
    fn target(&self) -> PyResult<PathBuf> {
        self.with(|l| l.target().to_path_buf())
    }

    /// An edge on the trigger input (rising or falling); True when it started the
    /// waveform (the controller was armed for it).
    fn input_edge(&self, rising: bool) -> PyResult<bool> {
        self.with(|l| l.emulator().input_edge(rising))
    }

    /// Whether channel `channel`'s output is high `t_us` microseconds after the
    /// last trigger.
    fn level_at(&self, channel: u8, t_us: u64) -> PyResult<bool> {
        self.with(|l| l.emulator().device().level_at(channel, t_us))
    }

    /// Stop the emulator and remove the link.
    fn close(&self) {
        if let Ok(mut g) = self.linked.lock() {
            g.take();
        }
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    fn __exit__(&self, _t: Option<&Bound<'_, PyAny>>, _v: Option<&Bound<'_, PyAny>>, _tb: Option<&Bound<'_, PyAny>>) -> bool {
        self.close();
        false
    }

    fn __repr__(&self) -> String {
        format!("LedEmulator({:?})", self.link.display().to_string())
    }
}

pub(crate) fn add(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyCamera>()?;
    m.add_class::<PyFrame>()?;
    m.add_class::<FrameIter>()?;
    m.add_class::<PyLedController>()?;
    m.add_class::<PyLedEmulator>()?;
    m.add_function(wrap_pyfunction!(led_ports, m)?)?;
    Ok(())
}
