//! `rollcam.simulate` (a rolling-shutter capture of a known scene through a diffuser,
//! as `rollcam simulate` makes it) and `rollcam.analyze` (the measurements of `rollcam
//! analyze`, as arrays and dicts instead of files).

use crate::{f32_array, memory_error, to_python, value_error, PyTiming};
use ndarray::{ArrayView4, Axis, Ix4};
use numpy::{IntoPyArray, PyArray1, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rollcam::analysis::report::{analyze_video, AnalyzeOptions, Geometry, Region, VideoTiming};
use rollcam::model::capture::CaptureConfig;
use rollcam::sim::setup::{measured_psf, SceneKind};
use rollcam::sim::{psf_counts, SimParams, SimSetup};

/// One simulated capture and its truth.
#[pyclass(module = "rollcam", name = "Simulation", frozen, get_all)]
pub(crate) struct PySimulation {
    /// Raw image, ADU (dark level included, quantised, clamped): (rows, cols) float32.
    raw: Py<PyAny>,
    /// The PSF as a calibration records it (peak 50000 counts above the dark level),
    /// what `rollcam simulate` writes to psf.tiff: (rows, cols) float32.
    psf: Py<PyAny>,
    /// Ground-truth video on the reconstruction grid, ADU per frame interval:
    /// (frames, rows / downsample, cols / downsample) float32.
    truth: Py<PyAny>,
    /// The capture's timing.
    timing: PyTiming,
    /// The capture description (capture.toml's keys, with the simulation's provenance).
    config: Py<PyAny>,
    /// Frame interval of the truth, microseconds.
    frame_time_us: f64,
    /// Pixels that reached the full well or the ADC maximum.
    saturated_pixels: usize,
    /// Dark level of the raw image, ADU.
    dark_level_adu: f64,
    /// Conversion gain, ADU per photo-electron.
    gain_adu_per_e: f64,
}

#[pymethods]
impl PySimulation {
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let shape = |a: &Py<PyAny>| -> PyResult<String> { Ok(a.bind(py).getattr("shape")?.repr()?.to_string()) };
        Ok(format!("Simulation(raw {}, truth {}, frame_time_us={})", shape(&self.raw)?, shape(&self.truth)?, self.frame_time_us))
    }
}

/// Simulate one rolling-shutter capture of a known scene through a diffuser, as
/// `rollcam simulate` does with the same values (the same seed gives the same raw
/// image and truth).
///
/// scene: led-array, moving-disc, disc-over-texture or stack; psf: a measured PSF image
/// (rows, cols[, channels]) instead of the synthetic diffuser (dark-subtracted,
/// averaged over colours, box-downsampled by psf_downsample; its size becomes the
/// sensor's); stack: the frames of the stack scene (frames, rows, cols[, channels]);
/// params: the simulation's parameters by name (rows, cols, line_time_us,
/// exposure_us, shutter, downsample, binning, lenslets, aperture_fraction, leds,
/// period_us, duty, spacing_px, led_radius_px, e_per_us, disc_radius_px,
/// disc_px_per_ms, disc_contrast, stack_interval_us, read_noise_e, dark_level_adu,
/// noise, substeps, seed), each defaulting to `rollcam simulate`'s flag.
#[pyfunction]
#[pyo3(signature = (scene = "led-array", *, psf = None, psf_downsample = 1, stack = None, **params))]
pub(crate) fn simulate(
    py: Python<'_>,
    scene: &str,
    psf: Option<&Bound<'_, PyAny>>,
    psf_downsample: usize,
    stack: Option<&Bound<'_, PyAny>>,
    params: Option<&Bound<'_, PyDict>>,
) -> PyResult<PySimulation> {
    let kind: SceneKind = scene.parse().map_err(PyValueError::new_err)?;
    let p: SimParams = match params {
        None => SimParams::default(),
        Some(d) => {
            let text: String = py.import("json")?.call_method1("dumps", (d,))?.extract()?;
            serde_json::from_str(&text).map_err(|e| PyValueError::new_err(format!("simulate: {e}")))?
        }
    };
    p.check_sensor().map_err(value_error)?;
    let psf = match psf {
        None => py.allow_threads(|| p.synthetic_psf()).map_err(value_error)?,
        Some(obj) => {
            let (a, _) = f32_array(py, obj, "psf")?;
            let img = crate::image_view(&a, "psf")?;
            measured_psf(img, psf_downsample, "psf").map_err(value_error)?
        }
    };
    let (rows, cols) = psf.dim();
    let cfg = p.capture_config(rows, cols).map_err(|e| PyValueError::new_err(format!("invalid capture timing: {e}")))?;
    rollcam::io::budget::check_simulation(&cfg, 1, 1).map_err(memory_error)?;
    let stack_a = stack.map(|s| f32_array(py, s, "stack")).transpose()?;
    let stack4: Option<ArrayView4<f32>> = match &stack_a {
        None => None,
        Some((a, _)) => {
            let v = a.as_array();
            let v = match v.ndim() {
                3 => v.insert_axis(Axis(3)).into_dimensionality::<Ix4>().expect("four axes"),
                4 => v.into_dimensionality::<Ix4>().expect("four axes"),
                _ => return Err(PyValueError::new_err(format!("stack: expected a (frames, rows, cols[, channels]) array, got shape {:?}", a.shape()))),
            };
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(PyValueError::new_err(format!("stack: value {i} (in C order) is not finite: expected finite radiances")));
            }
            Some(v)
        }
    };
    let scene = p.scene(kind, rows, cols, stack4).map_err(|e| PyValueError::new_err(format!("scene {}: {e}", kind.name())))?;
    let setup = SimSetup::new(&p, cfg, psf, scene);
    let (cfg, s) = py.allow_threads(|| setup.simulate()).map_err(value_error)?;
    let psf = psf_counts(setup.psf.view(), setup.noise.dark_level_adu).index_axis_move(Axis(2), 0);
    Ok(PySimulation {
        config: to_python(py, &cfg)?.unbind(),
        timing: PyTiming::of_config(&cfg),
        raw: s.raw.into_dyn().into_pyarray(py).into_any().unbind(),
        psf: psf.into_dyn().into_pyarray(py).into_any().unbind(),
        truth: s.truth.into_dyn().into_pyarray(py).into_any().unbind(),
        frame_time_us: s.frame_time_us,
        saturated_pixels: s.saturated_pixels,
        dark_level_adu: s.dark_level_adu,
        gain_adu_per_e: s.gain_adu_per_e,
    })
}

fn region(obj: &Bound<'_, PyAny>) -> PyResult<Region> {
    if let Ok(s) = obj.extract::<String>() {
        return s.parse().map_err(PyValueError::new_err);
    }
    let v: Vec<usize> =
        obj.extract().map_err(|_| PyValueError::new_err("regions: expected (r0, r1, c0, c1) tuples of non-negative integers or 'r0,r1,c0,c1' strings"))?;
    match v[..] {
        [r0, r1, c0, c1] => Ok(Region { r0, r1, c0, c1 }),
        _ => Err(PyValueError::new_err(format!("regions: {} numbers, expected r0, r1, c0, c1 (four)", v.len()))),
    }
}

fn positive(name: &str, v: f64) -> PyResult<f64> {
    if !(v.is_finite() && v > 0.0) {
        return Err(PyValueError::new_err(format!("{name} = {v}: expected a positive number")));
    }
    Ok(v)
}

/// Measure a reconstructed video as `rollcam analyze` does: the regions' time courses
/// and power spectra in Hz, the theory of the capture's timing beside them, the dips
/// between spots, and with a geometry the angular resolution.
///
/// video: (frames, rows, cols[, channels]); timing: the capture's Timing (its
/// downsample is the video's against the raw sensor); regions: (r0, r1, c0, c1)
/// boxes (ends excluded), default the brightest spots; waveform_period_us, duty: a
/// square wave in the scene; distance_mm with pixel_pitch_um (and object_distance_mm):
/// angles. Returns analysis.json's content as a dict, each region with its `course`
/// and `frequency_hz`/`power` arrays.
#[pyfunction]
#[pyo3(signature = (video, timing, *, regions = None, waveform_period_us = None, duty = 0.5, max_spots = 8, trim_frames = 0,
    distance_mm = None, pixel_pitch_um = None, object_distance_mm = None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn analyze<'py>(
    py: Python<'py>,
    video: &Bound<'py, PyAny>,
    timing: &PyTiming,
    regions: Option<Vec<Bound<'py, PyAny>>>,
    waveform_period_us: Option<f64>,
    duty: f64,
    max_spots: usize,
    trim_frames: usize,
    distance_mm: Option<f64>,
    pixel_pitch_um: Option<f64>,
    object_distance_mm: Option<f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let (a, _) = f32_array(py, video, "video")?;
    let v = a.as_array();
    let v4 = match v.ndim() {
        3 => v.insert_axis(Axis(3)).into_dimensionality::<Ix4>().expect("four axes"),
        4 => v.into_dimensionality::<Ix4>().expect("four axes"),
        _ => return Err(PyValueError::new_err(format!("video: expected a (frames, rows, cols[, channels]) array, got shape {:?}", a.shape()))),
    };
    let (_, m, n, _) = v4.dim();
    let d = timing.downsample;
    let mut cfg = CaptureConfig::new(m * d, n * d, timing.line_time_us, timing.exposure_us, timing.shutter);
    cfg.downsample = d;
    cfg.binning = timing.binning;
    cfg.row_start_us = timing.row_start_us.clone();
    let vt = VideoTiming::from_config(&cfg, None, "timing").map_err(value_error)?;
    let geometry = match (distance_mm, pixel_pitch_um) {
        (Some(dm), Some(pp)) => Some(Geometry {
            distance_mm: positive("distance_mm", dm)?,
            pixel_pitch_um: positive("pixel_pitch_um", pp)?,
            object_distance_mm: object_distance_mm.map(|z| positive("object_distance_mm", z)).transpose()?,
        }),
        (None, None) => None,
        _ => return Err(PyValueError::new_err("angular resolution needs both distance_mm and pixel_pitch_um")),
    };
    let opts = AnalyzeOptions {
        regions: regions.unwrap_or_default().iter().map(region).collect::<PyResult<_>>()?,
        waveform_period_us,
        duty,
        max_spots,
        trim_frames,
        geometry,
        ..AnalyzeOptions::default()
    };
    let analysis = py.allow_threads(|| analyze_video(v4, &vt, &opts)).map_err(value_error)?;
    let out = to_python(py, &analysis)?;
    let listed = out.get_item("regions")?;
    for (i, r) in analysis.regions.iter().enumerate() {
        let d = listed.get_item(i)?;
        d.set_item("course", PyArray1::from_vec(py, r.course.clone()))?;
        d.set_item("frequency_hz", PyArray1::from_vec(py, r.spectrum.frequency_hz.clone()))?;
        d.set_item("power", PyArray1::from_vec(py, r.spectrum.power.clone()))?;
    }
    if let Some(c) = &analysis.combined {
        let d = PyDict::new(py);
        d.set_item("frequency_hz", PyArray1::from_vec(py, c.frequency_hz.clone()))?;
        d.set_item("power", PyArray1::from_vec(py, c.power.clone()))?;
        out.set_item("combined_spectrum", d)?;
    }
    Ok(out)
}
