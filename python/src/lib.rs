//! The `rollcam` Python module: the rolling-shutter imaging operator and the
//! reconstruction of one capture, NumPy arrays in and out.
//!
//! Arrays are taken as C-contiguous float32 (other dtypes and layouts are converted
//! once, by `numpy.ascontiguousarray`); results are new float32 arrays that own the
//! Rust buffers (no copy). The GIL is released while the operator runs and while a
//! reconstruction solves. Errors carry the library's messages: invalid values raise
//! `ValueError`, file errors `OSError` (`FileNotFoundError` for a missing file).

use ndarray::{ArrayView3, ArrayView4, Axis, Ix3, Ix4, IxDyn};
use numpy::{IntoPyArray, PyArray1, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use rollcam::io::cache::LipschitzCache;
use rollcam::io::output::Summary;
use rollcam::io::sensor_files::SensorFiles;
use rollcam::model::capture::{CaptureConfig, ConfigError, Fov};
use rollcam::model::keyframe::KeyFrameRef;
use rollcam::model::op::Operator;
use rollcam::model::prepare::KeyFrameImage;
use rollcam::model::rolling::RollingShutterModel;
use rollcam::model::scene::SceneSpec;
use rollcam::model::shutter::{ShutterMode, Timing};
use rollcam::request::capture::{CaptureOutcome, CaptureRequest};
use rollcam::request::RequestError;
use rollcam::sim::psf::{lenslet_psf as lenslet_psf_rs, LensletParams};
use rollcam::solve::lipschitz::power_iteration;
use rollcam::solve::problem::{SolveSettings, DEFAULT_ALPHA, DEFAULT_ITERS, DEFAULT_OBJ_TOL};
use rollcam::solve::reconstruct::Hooks;
use rollcam::solve::tau::{Tau, FALLBACK_TAU_REL, NOISE_TAU_PER_SIGMA, VIDEO_TAU_REL_FLOOR};
use rollcam::solve::trace::TraceRow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

mod bench;
mod sim;

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn memory_error(e: impl std::fmt::Display) -> PyErr {
    pyo3::exceptions::PyMemoryError::new_err(e.to_string())
}

/// An operating-system error as `FileNotFoundError` (missing file) or `OSError`.
fn os_error(kind: std::io::ErrorKind, message: String) -> PyErr {
    if kind == std::io::ErrorKind::NotFound {
        PyFileNotFoundError::new_err(message)
    } else {
        PyOSError::new_err(message)
    }
}

/// A file error: `OSError` (`FileNotFoundError` for a missing file or folder) when the
/// system refused or the path is not there, `MemoryError` for a file over the memory
/// budget, else `ValueError` (a file whose content is not what was expected).
fn io_error(e: rollcam::io::IoError) -> PyErr {
    match &e {
        rollcam::io::IoError::Os { source, .. } => os_error(source.kind(), e.to_string()),
        rollcam::io::IoError::TooLarge { .. } => memory_error(e),
        _ if !e.path().exists() => os_error(std::io::ErrorKind::NotFound, e.to_string()),
        _ => value_error(e),
    }
}

fn config_error(e: ConfigError) -> PyErr {
    match &e {
        ConfigError::Read { source, .. } => os_error(source.kind(), e.to_string()),
        _ => value_error(e),
    }
}

/// `obj` as a C-contiguous float32 array (converted by NumPy when it is not one), and
/// the full scale of its original integer dtype (`uint8`: 255, `uint16`: 65535), which
/// the sensor handling uses as the raw file's full scale.
fn f32_array<'py>(py: Python<'py>, obj: &Bound<'py, PyAny>, what: &str) -> PyResult<(PyReadonlyArrayDyn<'py, f32>, Option<f64>)> {
    let np = py.import("numpy")?;
    let full_scale = match obj.getattr("dtype").and_then(|d| d.getattr("str")).and_then(|s| s.extract::<String>()) {
        Ok(s) if s.ends_with("u1") => Some(255.0),
        Ok(s) if s.ends_with("u2") => Some(65535.0),
        _ => None,
    };
    let kw = PyDict::new(py);
    kw.set_item("dtype", np.getattr("float32")?)?;
    let a = np.call_method("ascontiguousarray", (obj,), Some(&kw)).map_err(|e| PyValueError::new_err(format!("{what}: not an array of numbers: {e}")))?;
    let a = a.downcast_into::<PyArrayDyn<f32>>().map_err(PyErr::from)?;
    Ok((a.try_readonly().map_err(|e| PyValueError::new_err(format!("{what}: {e}")))?, full_scale))
}

/// A `(rows, cols)` or `(rows, cols, channels)` image as `(rows, cols, channels)`.
fn image_view<'a>(a: &'a PyReadonlyArrayDyn<'_, f32>, what: &str) -> PyResult<ArrayView3<'a, f32>> {
    let v = a.as_array();
    match v.ndim() {
        2 => Ok(v.insert_axis(Axis(2)).into_dimensionality::<Ix3>().expect("three axes")),
        3 => Ok(v.into_dimensionality::<Ix3>().expect("three axes")),
        _ => Err(PyValueError::new_err(format!("{what}: expected a (rows, cols) or (rows, cols, channels) array, got shape {:?}", a.shape()))),
    }
}

fn parse<T: std::str::FromStr<Err = String>>(s: &str) -> PyResult<T> {
    s.parse::<T>().map_err(PyValueError::new_err)
}

/// The timing of one raw capture.
#[pyclass(module = "rollcam", name = "Timing", frozen, eq)]
#[derive(Clone, Debug, PartialEq)]
struct PyTiming {
    line_time_us: f64,
    exposure_us: f64,
    shutter: ShutterMode,
    downsample: usize,
    binning: usize,
    row_start_us: Option<Vec<f64>>,
}

impl PyTiming {
    /// The library's timing for a sensor of `raw_rows` rows.
    fn core(&self, raw_rows: usize) -> Timing {
        Timing {
            downsample: self.downsample,
            binning: self.binning,
            row_start_us: self.row_start_us.clone(),
            ..Timing::new(raw_rows, self.line_time_us, self.exposure_us, self.shutter)
        }
    }

    fn of_config(cfg: &CaptureConfig) -> PyTiming {
        PyTiming {
            line_time_us: cfg.line_time_us,
            exposure_us: cfg.exposure_us,
            shutter: cfg.shutter,
            downsample: cfg.downsample,
            binning: cfg.binning,
            row_start_us: cfg.row_start_us.clone(),
        }
    }
}

#[pymethods]
impl PyTiming {
    #[new]
    #[pyo3(signature = (line_time_us, exposure_us, shutter = "dual", downsample = 1, binning = 1))]
    fn new(line_time_us: f64, exposure_us: f64, shutter: &str, downsample: usize, binning: usize) -> PyResult<Self> {
        let t = PyTiming { line_time_us, exposure_us, shutter: parse(shutter)?, downsample, binning, row_start_us: None };
        // Every check that does not depend on the sensor's size (that one comes with the
        // raw image or the PSF).
        t.core(downsample.max(1)).validate().map_err(value_error)?;
        Ok(t)
    }

    #[getter]
    fn line_time_us(&self) -> f64 {
        self.line_time_us
    }
    #[getter]
    fn exposure_us(&self) -> f64 {
        self.exposure_us
    }
    #[getter]
    fn shutter(&self) -> &'static str {
        self.shutter.name()
    }
    #[getter]
    fn downsample(&self) -> usize {
        self.downsample
    }
    #[getter]
    fn binning(&self) -> usize {
        self.binning
    }
    /// Frame interval of the video, microseconds (downsample x binning x line time).
    #[getter]
    fn frame_time_us(&self) -> f64 {
        self.core(1).frame_time_us()
    }

    /// Shutter weights W[row, frame] of a sensor with `raw_rows` rows (rows of the
    /// downsampled grid x video frames), float32.
    fn weights<'py>(&self, py: Python<'py>, raw_rows: usize) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let w = self.core(raw_rows).weights().map_err(value_error)?;
        let shape = IxDyn(&[w.rows(), w.frames()]);
        Ok(ndarray::ArrayD::from_shape_vec(shape, w.as_slice().to_vec()).expect("rows x frames").into_pyarray(py))
    }

    /// Frames of the video of a sensor with `raw_rows` rows.
    fn frames(&self, raw_rows: usize) -> PyResult<usize> {
        Ok(self.core(raw_rows).weights().map_err(value_error)?.frames())
    }

    fn __repr__(&self) -> String {
        format!(
            "Timing(line_time_us={}, exposure_us={}, shutter={:?}, downsample={}, binning={})",
            self.line_time_us,
            self.exposure_us,
            self.shutter.name(),
            self.downsample,
            self.binning
        )
    }
}

/// The imaging operator `A`: video (frames, rows, cols) -> sensor image (rows, cols).
#[pyclass(module = "rollcam", name = "ImagingOperator", frozen)]
struct PyOperator {
    model: RollingShutterModel,
}

impl PyOperator {
    fn video_shape(&self) -> Vec<usize> {
        self.model.input_shape()
    }
    fn sensor_shape(&self) -> Vec<usize> {
        self.model.output_shape()
    }

    /// `x` (any shape with `len` entries) as float32, and `shape` for the result.
    fn apply<'py>(&self, py: Python<'py>, x: &Bound<'py, PyAny>, adjoint: bool) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let (from, to, what) =
            if adjoint { (self.sensor_shape(), self.video_shape(), "adjoint: b") } else { (self.video_shape(), self.sensor_shape(), "forward: v") };
        let (a, _) = f32_array(py, x, what)?;
        let n: usize = from.iter().product();
        if a.len() != n {
            return Err(PyValueError::new_err(format!("{what}: shape {:?} has {} entries, expected shape {from:?} ({n} entries)", a.shape(), a.len())));
        }
        let src = a.as_slice().map_err(value_error)?;
        let mut out = vec![0.0f32; to.iter().product()];
        py.allow_threads(|| if adjoint { self.model.adjoint(src, &mut out) } else { self.model.forward(src, &mut out) });
        Ok(ndarray::ArrayD::from_shape_vec(IxDyn(&to), out).expect("output shape").into_pyarray(py))
    }
}

#[pymethods]
impl PyOperator {
    #[new]
    #[pyo3(signature = (psf, timing, fov = "sensor"))]
    fn new(py: Python<'_>, psf: &Bound<'_, PyAny>, timing: &PyTiming, fov: &str) -> PyResult<Self> {
        let fov: Fov = parse(fov)?;
        let (a, _) = f32_array(py, psf, "psf")?;
        if a.ndim() != 2 {
            return Err(PyValueError::new_err(format!("psf: expected a (rows, cols) array on the video grid, got shape {:?}", a.shape())));
        }
        let (rows, cols) = (a.shape()[0], a.shape()[1]);
        if rows == 0 || cols == 0 {
            return Err(PyValueError::new_err(format!("psf: shape {:?} is empty", a.shape())));
        }
        if let Some((i, _)) = a.as_slice().map_err(value_error)?.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(PyValueError::new_err(format!("psf: contains NaN or infinite values (first at row {}, col {})", i / cols, i % cols)));
        }
        // The PSF is on the grid the video is solved on: the sensor had `downsample`
        // times its rows.
        let weights = timing.core(rows * timing.downsample).weights().map_err(value_error)?;
        let psf = a.as_slice().map_err(value_error)?;
        let model = py.allow_threads(|| RollingShutterModel::of_psf(psf, rows, cols, fov, weights));
        Ok(PyOperator { model })
    }

    /// (video shape (frames, rows, cols), sensor shape (rows, cols)).
    #[getter]
    fn shape<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let v = PyTuple::new(py, self.video_shape())?;
        let s = PyTuple::new(py, self.sensor_shape())?;
        PyTuple::new(py, [v.into_any(), s.into_any()])
    }

    /// `A v`: a video (frames, rows, cols) to the sensor image (rows, cols).
    fn forward<'py>(&self, py: Python<'py>, v: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        self.apply(py, v, false)
    }

    /// `A^T b`: a sensor image (rows, cols) to a video (frames, rows, cols).
    fn adjoint<'py>(&self, py: Python<'py>, b: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        self.apply(py, b, true)
    }

    /// The largest eigenvalue of `A^T A` (the Lipschitz constant of the gradient of
    /// `0.5 ||A v - b||^2`), by power iteration from a fixed start.
    #[pyo3(signature = (max_iters = 300, tol = 1e-5))]
    fn lipschitz(&self, py: Python<'_>, max_iters: usize, tol: f64) -> f64 {
        py.allow_threads(|| power_iteration(&self.model, max_iters, tol, 0x5eed).lambda_max)
    }

    /// A `scipy.sparse.linalg.LinearOperator` on flattened float32 vectors (video
    /// entries in, sensor entries out).
    fn as_linear_operator<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let py = slf.py();
        let me = slf.get();
        let (n, m): (usize, usize) = (me.video_shape().iter().product(), me.sensor_shape().iter().product());
        let sla = py.import("scipy.sparse.linalg")?;
        let kw = PyDict::new(py);
        kw.set_item("shape", (m, n))?;
        kw.set_item("matvec", slf.getattr("_matvec")?)?;
        kw.set_item("rmatvec", slf.getattr("_rmatvec")?)?;
        kw.set_item("dtype", py.import("numpy")?.getattr("float32")?)?;
        sla.getattr("LinearOperator")?.call((), Some(&kw))
    }

    fn _matvec<'py>(&self, py: Python<'py>, x: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        Ok(self.apply(py, x, false)?.reshape([self.sensor_shape().iter().product::<usize>()])?.into_any())
    }

    fn _rmatvec<'py>(&self, py: Python<'py>, y: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        Ok(self.apply(py, y, true)?.reshape([self.video_shape().iter().product::<usize>()])?.into_any())
    }

    fn __repr__(&self) -> String {
        format!("ImagingOperator(video {:?} -> sensor {:?})", self.video_shape(), self.sensor_shape())
    }
}

/// A reconstructed video with its trace and summary.
#[pyclass(module = "rollcam", name = "Reconstruction", frozen, get_all)]
struct PyReconstruction {
    /// (frames, rows, cols) for one channel, (frames, rows, cols, channels) for more.
    video: Py<PyAny>,
    /// Per iteration: channel, iteration, seconds, objective, data_term, tv_term,
    /// rel_change, psnr, rel_error (NaN without a truth).
    trace: Py<PyDict>,
    /// What summary.json records.
    summary: Py<PyAny>,
    /// Frame interval, microseconds.
    frame_time_us: f64,
    /// Whether the callback stopped the solve.
    stopped: bool,
}

#[pymethods]
impl PyReconstruction {
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let shape = self.video.bind(py).getattr("shape")?.repr()?.to_string();
        Ok(format!("Reconstruction(video shape {shape}, frame_time_us={}, stopped={})", self.frame_time_us, self.stopped))
    }
}

fn row_dict<'py>(py: Python<'py>, channel: usize, r: &TraceRow) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("channel", channel)?;
    d.set_item("iteration", r.iteration)?;
    d.set_item("seconds", r.seconds)?;
    d.set_item("objective", r.objective)?;
    d.set_item("data_term", r.data_term)?;
    d.set_item("tv_term", r.tv_term)?;
    d.set_item("rel_change", r.rel_change)?;
    d.set_item("psnr", r.psnr_db)?;
    d.set_item("rel_error", r.rel_error)?;
    Ok(d)
}

/// The Lipschitz cache a `cache` argument names: None: the default location (honours
/// `ROLLCAM_CACHE_DIR`), False: none, a path: that folder.
fn cache_of(cache: Option<&Bound<'_, PyAny>>) -> PyResult<LipschitzCache> {
    let Some(c) = cache else { return Ok(LipschitzCache::default_location()) };
    if let Ok(b) = c.extract::<bool>() {
        return Ok(if b { LipschitzCache::default_location() } else { LipschitzCache::disabled() });
    }
    let p: PathBuf = c.extract().map_err(|_| PyValueError::new_err("cache: expected None, True, False or a folder path"))?;
    Ok(LipschitzCache::at(&p))
}

/// A Python dict (JSON-like values) as a TOML table.
fn toml_table(py: Python<'_>, d: &Bound<'_, PyAny>, what: &str) -> PyResult<toml::Table> {
    let text: String = py.import("json")?.call_method1("dumps", (d,))?.extract()?;
    serde_json::from_str::<toml::Table>(&text).map_err(|e| PyValueError::new_err(format!("{what}: {e}")))
}

/// A truth video as (frames, rows, cols, channels).
fn truth_view<'a>(t: &'a PyReadonlyArrayDyn<'_, f32>) -> PyResult<ArrayView4<'a, f32>> {
    let v = t.as_array();
    match v.ndim() {
        3 => Ok(v.insert_axis(Axis(3)).into_dimensionality::<Ix4>().expect("four axes")),
        4 => Ok(v.into_dimensionality::<Ix4>().expect("four axes")),
        _ => Err(PyValueError::new_err(format!("truth: expected a (frames, rows, cols) or (frames, rows, cols, channels) array, got shape {:?}", t.shape()))),
    }
}

/// `keyframes`: a list of dicts, each a `[[keyframes]]` table of the capture
/// description (start_us, exposure_us, optional dark_level, gain, affine) with the
/// key frame's `image` as an array in place of its file (and an optional lens blur
/// `psf` as an array); `file` is only a name for messages (default `keyframes[i]`).
fn keyframe_images(py: Python<'_>, list: &Bound<'_, PyAny>) -> PyResult<Vec<KeyFrameImage>> {
    let mut out = Vec::new();
    for (i, item) in list.try_iter().map_err(|_| PyValueError::new_err("keyframes: expected a list of dicts"))?.enumerate() {
        let item = item?;
        let d =
            item.downcast::<PyDict>().map_err(|_| PyValueError::new_err(format!("keyframes[{i}]: expected a dict with image, start_us and exposure_us")))?;
        let name = format!("keyframes[{i}]");
        let array = |key: &str| -> PyResult<Option<(ndarray::Array3<f32>, Option<f64>)>> {
            match d.get_item(key)? {
                None => Ok(None),
                Some(v) if v.is_none() => Ok(None),
                Some(v) => {
                    let what = format!("{name}.{key}");
                    let (a, full_scale) = f32_array(py, &v, &what)?;
                    Ok(Some((image_view(&a, &what)?.to_owned(), full_scale)))
                }
            }
        };
        let (image, full_scale) = array("image")?.ok_or_else(|| PyValueError::new_err(format!("{name}: expected an image (an array)")))?;
        let psf = array("psf")?.map(|(p, _)| p);
        let table = PyDict::new(py);
        for (k, v) in d.iter() {
            let key: String = k.extract()?;
            if key != "image" && key != "psf" {
                table.set_item(key, v)?;
            }
        }
        if !table.contains("file")? {
            table.set_item("file", &name)?;
        }
        let spec: KeyFrameRef =
            toml::Value::Table(toml_table(py, table.as_any(), &name)?).try_into().map_err(|e| PyValueError::new_err(format!("{name}: {e}")))?;
        spec.validate(i).map_err(|e| PyValueError::new_err(format!("{name}: {e}")))?;
        out.push(KeyFrameImage { name: spec.file.clone(), spec, image, full_scale, psf });
    }
    Ok(out)
}

fn to_python<'py>(py: Python<'py>, v: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(v).map_err(value_error)?;
    py.import("json")?.call_method1("loads", (text,))
}

/// `tau_rel`: a number, "noise" (the default: from the raw's noise) or "auto" (chosen
/// by held-out pixels, `--tau-rel auto`).
#[derive(FromPyObject)]
enum TauRelArg {
    Number(f32),
    Word(String),
}

/// Reconstruct a video from one raw rolling-shutter capture and its PSF, as
/// `rollcam reconstruct` does with the same values.
///
/// raw, psf: (rows, cols) or (rows, cols, channels) arrays of one size. tau: absolute
/// TV weight (default: tau_rel times max(A^T b)); tau_rel: a number, "noise" (the
/// default: NOISE_TAU_PER_SIGMA times the raw's noise over sqrt(frames), a video's at
/// least VIDEO_TAU_REL_FLOOR times max(A^T b);
/// summary["params"]["tau_choice"] says what it read) or "auto" (chosen by held-out
/// pixels on a mostly still scene, from the noise rule's weight; summary["tau_search"]
/// says how); alpha: temporal TV weight relative
/// to the spatial ones; solver: fista, fista-restart (default), mfista, admm, pgd or admm-split;
/// start: where the video solve starts, auto (default: the still image solved first,
/// repeated in every frame), still or zero;
/// dark_level: black offset of the raw, and of the psf unless psf_dark_level is given
/// (estimated when None); psf_dark_level: the psf's own black offset; scene: the [scene] keys of
/// capture.toml as a dict; truth: video (frames, rows, cols[, channels]) for PSNR in
/// the trace; calibration: a bench calibration folder (`rollcam calibrate`'s: dark
/// frame, defects, flat field, and its psf.tiff when psf is None); background: a
/// raw frame of the background as shot; keyframes: frames of a second, global-shutter
/// camera, a list of dicts, each a capture description's [[keyframes]] table (start_us,
/// exposure_us, optional dark_level, gain, affine) with `image` an array in place of
/// its file and an optional lens blur `psf` array; callback(row): called after every iteration with a dict (channel,
/// iteration, seconds, objective, data_term, tv_term, rel_change, psnr, rel_error),
/// stops the solve by returning True; cache: where the Lipschitz constant is kept
/// (None: $ROLLCAM_CACHE_DIR or the user cache, False: not kept, a path: that folder).
/// Returns a Reconstruction (video, trace, summary, frame_time_us, stopped).
#[pyfunction]
#[pyo3(signature = (raw, psf, timing, *, tau = None, tau_rel = TauRelArg::Word("noise".into()), alpha = DEFAULT_ALPHA, solver = None, iters = DEFAULT_ITERS,
    rel_tol = 0.0, obj_tol = DEFAULT_OBJ_TOL, time_budget_s = None, tv_prox = "auto", start = "auto", fov = "sensor", dark_level = None, saturation_level = None,
    psf_dark_level = None, scene = None, truth = None, calibration = None, background = None, keyframes = None, callback = None, cache = None))]
#[allow(clippy::too_many_arguments)]
fn reconstruct(
    py: Python<'_>,
    raw: &Bound<'_, PyAny>,
    psf: Option<&Bound<'_, PyAny>>,
    timing: &PyTiming,
    tau: Option<f32>,
    tau_rel: TauRelArg,
    alpha: f32,
    solver: Option<&str>,
    iters: usize,
    rel_tol: f64,
    obj_tol: f64,
    time_budget_s: Option<f64>,
    tv_prox: &str,
    start: &str,
    fov: &str,
    dark_level: Option<f64>,
    saturation_level: Option<f64>,
    psf_dark_level: Option<f64>,
    scene: Option<&Bound<'_, PyAny>>,
    truth: Option<&Bound<'_, PyAny>>,
    calibration: Option<PathBuf>,
    background: Option<PathBuf>,
    keyframes: Option<&Bound<'_, PyAny>>,
    callback: Option<Py<PyAny>>,
    cache: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyReconstruction> {
    let tau_rel = match tau_rel {
        TauRelArg::Number(v) => Tau::Relative(v),
        TauRelArg::Word(w) => w.parse::<Tau>().map_err(|e| PyValueError::new_err(format!("tau_rel = {w:?}: {e}")))?,
    };
    let tau = Tau::from_given(tau, tau_rel).ok_or_else(|| {
        PyValueError::new_err(format!("tau = {}: expected no absolute tau when tau_rel is auto (chosen by held-out pixels)", tau.unwrap_or_default()))
    })?;
    let settings = SolveSettings {
        tau,
        alpha,
        iters,
        rel_tol,
        time_budget_s,
        obj_tol,
        solver: solver.map(parse).transpose()?.unwrap_or_default(),
        tv_prox: parse(tv_prox)?,
        start: parse(start)?,
        ..SolveSettings::default()
    };
    let settings = settings.validate().map_err(|e| PyValueError::new_err(format!("{} = {}: expected {}", e.field, e.value, e.expected)))?;
    if let Some(d) = psf_dark_level.filter(|d| !(d.is_finite() && *d >= 0.0)) {
        return Err(PyValueError::new_err(format!("psf_dark_level = {d}: expected the PSF's black offset, finite and >= 0 counts")));
    }
    let (raw_a, full_scale) = f32_array(py, raw, "raw")?;
    let raw3 = image_view(&raw_a, "raw")?;
    // The sensor's calibration folder and background frame, as --calibration and
    // --background give them.
    let mut sensor = py.allow_threads(|| SensorFiles::load(calibration.as_deref(), background.as_deref(), None, None)).map_err(io_error)?;
    sensor.keyframes = keyframes.map(|k| keyframe_images(py, k)).transpose()?.unwrap_or_default();
    let psf_a = psf.map(|p| f32_array(py, p, "psf")).transpose()?;
    let (psf3, psf_name, psf_clean) = match (&psf_a, sensor.psf()) {
        (Some((a, _)), _) => (image_view(a, "psf")?, "psf".to_string(), false),
        (None, Some((name, img))) => (img.view(), name, true),
        (None, None) => {
            return Err(PyValueError::new_err(format!(
                "no PSF: give psf (an image of a point source through the same optics), or calibration= a folder that has a psf.tiff{}",
                sensor.calibration_name().map(|d| format!(" ({d} has none)")).unwrap_or_default()
            )))
        }
    };
    let (rows, cols, _) = raw3.dim();
    let mut cfg = CaptureConfig::new(rows, cols, timing.line_time_us, timing.exposure_us, timing.shutter);
    cfg.downsample = timing.downsample;
    cfg.binning = timing.binning;
    cfg.row_start_us = timing.row_start_us.clone();
    cfg.dark_level = dark_level;
    cfg.saturation_level = saturation_level;
    cfg.fov = parse(fov)?;
    cfg.validate().map_err(|e| PyValueError::new_err(format!("invalid capture description: {e}")))?;
    let scene = scene.map(|s| toml_table(py, s, "scene")).transpose()?;
    // No `scene`: nothing declared (as the command line without scene flags).
    let scene = scene.map(|t| SceneSpec::from_table(Some(&t)).map_err(|e| PyValueError::new_err(format!("scene declaration: {e}")))).transpose()?;
    let truth_a = truth.map(|t| f32_array(py, t, "truth")).transpose()?;
    let truth4 = truth_a.as_ref().map(|(t, _)| truth_view(t)).transpose()?;
    let cache = cache_of(cache)?;
    let stop = AtomicBool::new(false);
    let failure: Mutex<Option<PyErr>> = Mutex::new(None);
    let on_row = |ch: usize, row: &TraceRow| {
        Python::with_gil(|py| {
            let result = (|| -> PyResult<bool> {
                py.check_signals()?;
                match &callback {
                    Some(cb) => cb.bind(py).call1((row_dict(py, ch, row)?,))?.is_truthy(),
                    None => Ok(false),
                }
            })();
            match result {
                Ok(false) => {}
                Ok(true) => stop.store(true, Ordering::SeqCst),
                Err(e) => {
                    failure.lock().unwrap().get_or_insert(e);
                    stop.store(true, Ordering::SeqCst);
                }
            }
        })
    };
    let request = CaptureRequest::new(raw3, "raw", psf3, &psf_name, &cfg, &sensor, &settings)
        .with_full_scale(full_scale)
        .with_clean_psf(psf_clean)
        .with_psf_dark_level(psf_dark_level)
        .with_scene(scene)
        .with_truth(truth4.map(|t| (t, "truth")));
    let solved = py.allow_threads(|| request.run(&cache, &Hooks { on_row: &on_row, stop: &stop }));
    if let Some(e) = failure.lock().unwrap().take() {
        return Err(e);
    }
    let CaptureOutcome { reconstruction: rec, params, prepared, seconds } = solved.map_err(|e| match e {
        RequestError::Budget(e) => pyo3::exceptions::PyMemoryError::new_err(e.to_string()),
        e => PyValueError::new_err(e.to_string()),
    })?;
    let stopped = stop.load(Ordering::SeqCst);

    let inputs = request.inputs();
    let c = rec.video.dim().3;
    let summary = Summary::new(&rec, &cfg, &params, &inputs, &prepared, seconds, Vec::new());
    let summary = to_python(py, &summary)?;
    summary.set_item("stopped", stopped)?;

    let trace = PyDict::new(py);
    let rows: Vec<(usize, &TraceRow)> = rec.channels.iter().flat_map(|ch| ch.trace.iter().map(move |r| (ch.channel, r))).collect();
    let col = |f: fn(&TraceRow) -> f64| PyArray1::from_vec(py, rows.iter().map(|(_, r)| f(r)).collect());
    trace.set_item("channel", PyArray1::from_vec(py, rows.iter().map(|(c, _)| *c as i64).collect()))?;
    trace.set_item("iteration", PyArray1::from_vec(py, rows.iter().map(|(_, r)| r.iteration as i64).collect()))?;
    trace.set_item("seconds", col(|r| r.seconds))?;
    trace.set_item("objective", col(|r| r.objective))?;
    trace.set_item("data_term", col(|r| r.data_term))?;
    trace.set_item("tv_term", col(|r| r.tv_term))?;
    trace.set_item("rel_change", col(|r| r.rel_change))?;
    trace.set_item("psnr", col(|r| r.psnr_db.unwrap_or(f64::NAN)))?;
    trace.set_item("rel_error", col(|r| r.rel_error.unwrap_or(f64::NAN)))?;

    let frame_time_us = rec.frame_time_us;
    let video = if c == 1 { rec.video.index_axis_move(Axis(3), 0).into_pyarray(py).into_any() } else { rec.video.into_pyarray(py).into_any() };
    Ok(PyReconstruction { video: video.unbind(), trace: trace.unbind(), summary: summary.unbind(), frame_time_us, stopped })
}

/// A synthetic random-lenslet diffuser PSF of a `rows x cols` sensor (non-negative,
/// unit sum), deterministic for a seed: the simulator's PSF.
#[pyfunction]
#[pyo3(signature = (rows, cols, *, seed = 0, lenslets = 48, focal_spread = 0.04, defocus = 0.01, aperture_fraction = 0.8, supersample = 4, blur_px = 1.0))]
#[allow(clippy::too_many_arguments)]
fn lenslet_psf<'py>(
    py: Python<'py>,
    rows: usize,
    cols: usize,
    seed: u64,
    lenslets: usize,
    focal_spread: f64,
    defocus: f64,
    aperture_fraction: f64,
    supersample: usize,
    blur_px: f64,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let params = LensletParams { lenslets, focal_spread, defocus, aperture_fraction, supersample, blur_px };
    rollcam::io::ByteBudget::system()
        .check_array(|| format!("a {rows} x {cols} PSF"), &[rows, cols], 4)
        .map_err(|e| pyo3::exceptions::PyMemoryError::new_err(e.to_string()))?;
    let psf = py.allow_threads(|| lenslet_psf_rs(rows, cols, &params, seed)).map_err(value_error)?;
    Ok(psf.into_dyn().into_pyarray(py))
}

fn load<'py>(py: Python<'py>, path: &Path) -> PyResult<(PyTiming, Bound<'py, PyAny>)> {
    let cfg = CaptureConfig::load(path).map_err(config_error)?;
    cfg.validate().map_err(|e| PyValueError::new_err(format!("{}: invalid capture description: {e}", path.display())))?;
    Ok((PyTiming::of_config(&cfg), to_python(py, &cfg)?))
}

/// Read a capture description (capture.toml): its Timing and every key as a dict.
#[pyfunction]
fn load_config(py: Python<'_>, path: PathBuf) -> PyResult<(PyTiming, Bound<'_, PyAny>)> {
    load(py, &path)
}

/// Read the capture.toml of a capture folder: its Timing and every key as a dict.
#[pyfunction]
fn load_capture(py: Python<'_>, folder: PathBuf) -> PyResult<(PyTiming, Bound<'_, PyAny>)> {
    if !folder.is_dir() {
        return Err(os_error(std::io::ErrorKind::NotFound, format!("{}: no such capture folder", folder.display())));
    }
    load(py, &folder.join("capture.toml"))
}

/// Read an image file as rollcam's commands read it (TIFF, PNG, NPY; 8/16-bit or
/// float): (rows, cols) float32 for one channel, (rows, cols, channels) for more, in
/// the file's own units. page: 1-based page of a multi-page TIFF (refused without it).
#[pyfunction]
#[pyo3(signature = (path, *, page = None))]
fn read_image<'py>(py: Python<'py>, path: PathBuf, page: Option<usize>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let img = py.allow_threads(|| rollcam::io::read_image_page(&path, page)).map_err(io_error)?;
    Ok(if img.dim().2 == 1 { img.index_axis_move(Axis(2), 0).into_dyn().into_pyarray(py) } else { img.into_dyn().into_pyarray(py) })
}

/// Reconstruction of rolling-shutter captures through a diffuser, and its imaging
/// operator, from NumPy.
#[pymodule]
#[pyo3(name = "rollcam")]
fn rollcam_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // The solve defaults reconstruct() uses (the same constants as the command line).
    m.add("FALLBACK_TAU_REL", FALLBACK_TAU_REL)?;
    m.add("NOISE_TAU_PER_SIGMA", NOISE_TAU_PER_SIGMA)?;
    m.add("VIDEO_TAU_REL_FLOOR", VIDEO_TAU_REL_FLOOR)?;
    m.add("DEFAULT_ITERS", DEFAULT_ITERS)?;
    m.add("DEFAULT_OBJ_TOL", DEFAULT_OBJ_TOL)?;
    m.add("SHUTTER_MODES", PyList::new(m.py(), ShutterMode::ALL.iter().map(|s| s.name()))?)?;
    m.add_class::<PyTiming>()?;
    m.add_class::<PyOperator>()?;
    m.add_class::<PyReconstruction>()?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(load_config, m)?)?;
    m.add_function(wrap_pyfunction!(load_capture, m)?)?;
    m.add_function(wrap_pyfunction!(lenslet_psf, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    // Optional parts this build has (`aravis`: GenICam cameras).
    let features: &[&str] = if cfg!(feature = "aravis") { &["aravis"] } else { &[] };
    m.add("FEATURES", PyList::new(m.py(), features)?)?;
    m.add("SCENES", PyList::new(m.py(), rollcam::sim::setup::SceneKind::ALL.iter().map(|s| s.name()))?)?;
    m.add_class::<sim::PySimulation>()?;
    m.add_function(wrap_pyfunction!(sim::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(sim::analyze, m)?)?;
    bench::add(m)?;
    Ok(())
}
