"""Video from one rolling-shutter photograph taken through a diffuser.

Arrays go in as anything NumPy converts to float32 (converted once to a C-contiguous
float32 array when they are not one) and come out as new float32 arrays. The GIL is
released while the operator runs and while a reconstruction solves. Invalid values
raise ValueError, file errors OSError (FileNotFoundError for a missing file), with
the messages of the command-line tool.
"""

import os
from typing import Any, Callable, Dict, Iterator, List, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
SHUTTER_MODES: list[str]
"""The shutter modes a Timing takes: global, rolling, dual, dual-center-out."""
SCENES: list[str]
"""The scenes simulate() shows: led-array, moving-disc, disc-over-texture, stack."""
FALLBACK_TAU_REL: float
"""The TV weight relative to max(A^T b) where the raw's noise cannot be measured."""
NOISE_TAU_PER_SIGMA: float
"""The default (noise) rule: tau = NOISE_TAU_PER_SIGMA * sigma / sqrt(frames), a video's at least VIDEO_TAU_REL_FLOOR times max(A^T b)."""
VIDEO_TAU_REL_FLOOR: float
"""The smallest TV weight relative to max(A^T b) the noise rule gives a video."""
DEFAULT_ITERS: int
"""reconstruct()'s default cap on solver iterations."""
DEFAULT_OBJ_TOL: float
"""reconstruct()'s default convergence test: the objective's relative change per iteration."""
FEATURES: list[str]
"""Optional parts this build has: "aravis" (GenICam cameras)."""

ArrayLike = npt.ArrayLike
F32Array = npt.NDArray[np.float32]

class Timing:
    """The timing of one raw capture.

    line_time_us: delay between the starts of consecutive rows (us); exposure_us:
    exposure of every row (us, at least one line time); shutter: global, rolling,
    dual or dual-center-out; downsample: spatial factor d (box mean of d x d raw
    pixels); binning: temporal factor b (frames of b effective line times).
    Raises ValueError for values no capture can have.
    """

    def __init__(
        self,
        line_time_us: float,
        exposure_us: float,
        shutter: str = "dual",
        downsample: int = 1,
        binning: int = 1,
    ) -> None: ...
    @property
    def line_time_us(self) -> float: ...
    @property
    def exposure_us(self) -> float: ...
    @property
    def shutter(self) -> str: ...
    @property
    def downsample(self) -> int: ...
    @property
    def binning(self) -> int: ...
    @property
    def frame_time_us(self) -> float:
        """Frame interval of the video: downsample x binning x line time (us)."""
    def weights(self, raw_rows: int) -> F32Array:
        """Shutter weights W[row, frame] of a sensor with raw_rows rows."""
    def frames(self, raw_rows: int) -> int:
        """Frames of the video of a sensor with raw_rows rows."""

class ImagingOperator:
    """The imaging operator A: video (frames, rows, cols) -> sensor image (rows, cols).

    psf: the PSF on the grid the video is solved on (rows, cols), used as given (no
    dark subtraction or normalisation); timing: the capture's Timing (the sensor had
    downsample x rows raw rows); fov: "sensor" (the video is the sensor's field) or
    "full" (the video grid extends past the sensor by the PSF's support).
    """

    def __init__(self, psf: ArrayLike, timing: Timing, fov: str = "sensor") -> None: ...
    @property
    def shape(self) -> Tuple[Tuple[int, int, int], Tuple[int, int]]:
        """(video shape (frames, rows, cols), sensor shape (rows, cols))."""
    def forward(self, v: ArrayLike) -> F32Array:
        """A v: a video (any shape with frames*rows*cols entries) to the sensor image."""
    def adjoint(self, b: ArrayLike) -> F32Array:
        """A^T b: a sensor image (any shape with rows*cols entries) to a video."""
    def lipschitz(self, max_iters: int = 300, tol: float = 1e-5) -> float:
        """The largest eigenvalue of A^T A, by power iteration from a fixed start."""
    def as_linear_operator(self) -> Any:
        """A scipy.sparse.linalg.LinearOperator on flattened float32 vectors."""

class Reconstruction:
    """A reconstructed video with its trace and summary."""

    video: F32Array
    """(frames, rows, cols) for one channel, (frames, rows, cols, channels) for more."""
    trace: Dict[str, np.ndarray]
    """Per iteration (all channels one after the other): channel, iteration, seconds,
    objective, data_term, tv_term, rel_change, psnr, rel_error (NaN without a truth)."""
    summary: Dict[str, Any]
    """What summary.json records, and "stopped"."""
    frame_time_us: float
    stopped: bool
    """Whether the callback stopped the solve (the video is then the last iterate)."""

def reconstruct(
    raw: ArrayLike,
    psf: Optional[ArrayLike],
    timing: Timing,
    *,
    tau: Optional[float] = None,
    tau_rel: Union[float, str] = "noise",
    alpha: float = 5.0,
    solver: Optional[str] = None,
    iters: int = 600,
    rel_tol: float = 0.0,
    obj_tol: float = 1e-4,
    time_budget_s: Optional[float] = None,
    tv_prox: str = "auto",
    start: str = "auto",
    fov: str = "sensor",
    dark_level: Optional[float] = None,
    psf_dark_level: Optional[float] = None,
    saturation_level: Optional[float] = None,
    scene: Optional[Dict[str, Any]] = None,
    truth: Optional[ArrayLike] = None,
    calibration: Union[None, str, os.PathLike[str]] = None,
    background: Union[None, str, os.PathLike[str]] = None,
    keyframes: Optional[List[Dict[str, Any]]] = None,
    callback: Optional[Callable[[Dict[str, Any]], Optional[bool]]] = None,
    cache: Union[None, bool, str, os.PathLike[str]] = None,
) -> Reconstruction:
    """Reconstruct a video from one raw capture (rows, cols[, channels]) and its PSF
    (same size), as `rollcam reconstruct` does with the same values.

    tau: absolute TV weight (default: tau_rel times max(A^T b)); tau_rel: a number,
    "noise" (the default: NOISE_TAU_PER_SIGMA times the raw's noise over sqrt(frames),
    a video's at least VIDEO_TAU_REL_FLOOR times max(A^T b),
    summary["params"]["tau_choice"] says what it read) or "auto" (chosen by held-out
    pixels on a mostly still scene from the noise rule's weight, summary["tau_search"]
    says how; on a moving scene the noise rule's weight stands); alpha: temporal TV
    weight relative to the spatial ones; solver: fista, fista-restart (default),
    mfista, admm or pgd; dark_level: black offset of the raw, and of the psf unless psf_dark_level
    is given (estimated when None); psf_dark_level: the psf's own black offset;
    scene: the [scene] keys of capture.toml (support, frames, static, ...);
    truth: video (frames, rows, cols[, channels]) for PSNR in the trace;
    calibration: a bench calibration folder (`rollcam calibrate`'s: dark frame,
    defects, flat field; its psf.tiff is used when psf is None); background: a raw
    frame of the background as shot (subtracted);
    callback(row) is called after every iteration with a dict (channel, iteration,
    seconds, objective, data_term, tv_term, rel_change, psnr, rel_error) and stops the
    solve by returning True (an exception it raises stops it and is raised here);
    cache: where the Lipschitz constant is kept (None: $ROLLCAM_CACHE_DIR or the user
    cache, False: not kept, a path: that folder).
    """

def lenslet_psf(
    rows: int,
    cols: int,
    *,
    seed: int = 0,
    lenslets: int = 48,
    focal_spread: float = 0.04,
    defocus: float = 0.01,
    aperture_fraction: float = 0.8,
    supersample: int = 4,
    blur_px: float = 1.0,
) -> F32Array:
    """A synthetic random-lenslet diffuser PSF (rows, cols): non-negative, unit sum,
    deterministic for a seed (the simulator's PSF)."""

def load_config(path: Union[str, os.PathLike[str]]) -> Tuple[Timing, Dict[str, Any]]:
    """Read a capture.toml: its Timing and every key as a dict."""

def load_capture(folder: Union[str, os.PathLike[str]]) -> Tuple[Timing, Dict[str, Any]]:
    """Read the capture.toml of a capture folder: its Timing and every key as a dict."""

def read_image(path: Union[str, os.PathLike[str]], *, page: Optional[int] = None) -> F32Array:
    """Read an image file as rollcam's commands do (TIFF, PNG, NPY; 8/16-bit or float):
    (rows, cols) float32 for one channel, (rows, cols, channels) for more, in the
    file's own units. page: 1-based page of a multi-page TIFF (refused without it)."""

class Simulation:
    """One simulated capture and its truth."""

    raw: F32Array
    """Raw image, ADU (dark level included, quantised, clamped), (rows, cols)."""
    psf: F32Array
    """The PSF as a calibration records it (what psf.tiff holds), (rows, cols)."""
    truth: F32Array
    """Ground-truth video on the reconstruction grid, ADU per frame interval,
    (frames, rows / downsample, cols / downsample)."""
    timing: Timing
    config: Dict[str, Any]
    """The capture description (capture.toml's keys, with the simulation's provenance)."""
    frame_time_us: float
    saturated_pixels: int
    dark_level_adu: float
    gain_adu_per_e: float

def simulate(
    scene: str = "led-array",
    *,
    psf: Optional[ArrayLike] = None,
    psf_downsample: int = 1,
    stack: Optional[ArrayLike] = None,
    **params: Any,
) -> Simulation:
    """Simulate one rolling-shutter capture of a known scene through a diffuser, as
    `rollcam simulate` does with the same values (same seed: same raw and truth).

    scene: led-array, moving-disc, disc-over-texture or stack; psf: a measured PSF
    image instead of the synthetic diffuser (its size becomes the sensor's); stack:
    the frames of the stack scene (frames, rows, cols[, channels]); params, each
    defaulting to `rollcam simulate`'s flag: rows, cols, line_time_us, exposure_us,
    shutter, downsample, binning, lenslets, aperture_fraction, leds, period_us (a
    list), duty, spacing_px, led_radius_px, e_per_us, disc_radius_px, disc_px_per_ms,
    disc_contrast, stack_interval_us, read_noise_e, dark_level_adu, noise, substeps,
    seed. An unknown name raises ValueError.
    """

def analyze(
    video: ArrayLike,
    timing: Timing,
    *,
    regions: Optional[List[Union[Tuple[int, int, int, int], str]]] = None,
    waveform_period_us: Optional[float] = None,
    duty: float = 0.5,
    max_spots: int = 8,
    trim_frames: int = 0,
    distance_mm: Optional[float] = None,
    pixel_pitch_um: Optional[float] = None,
    object_distance_mm: Optional[float] = None,
) -> Dict[str, Any]:
    """Measure a video (frames, rows, cols[, channels]) as `rollcam analyze` does:
    analysis.json's content as a dict (theory, spots, regions, dips, angular,
    verdict), each region with its `course` (its sum per frame) and its spectrum
    (`frequency_hz`, `power`), and `combined_spectrum`. regions: (r0, r1, c0, c1)
    boxes, ends excluded (default: the brightest spots)."""

class Frame:
    """One frame from a camera."""

    pixels: np.ndarray
    """(height, width) uint16 for a complete frame; the samples that arrived, flat,
    for an incomplete or dropped one."""
    status: str
    """complete, incomplete or dropped."""
    meta: Dict[str, Any]
    """camera, frame_id, sequence, device/host timestamps (ns), width, height,
    bit_depth, valid_pixels, settings (as applied)."""

class Camera:
    """A camera as `rollcam capture --camera SPEC` opens it. A context manager.

    Errors: ValueError (a setting out of range or unsupported, a bad spec),
    FileNotFoundError (no such camera), TimeoutError (no frame in time), EOFError (the
    end of a replayed capture), OSError (other device failures).
    """

    @staticmethod
    def open(spec: str) -> "Camera":
        """sim:led-array, sim:moving-disc, replay:<folder>, aravis:<id> (needs the
        aravis feature: "aravis" in FEATURES)."""
    @property
    def spec(self) -> str: ...
    def info(self) -> Dict[str, Any]: ...
    def geometry(self) -> Dict[str, Any]: ...
    def capabilities(self) -> Dict[str, Any]: ...
    def configure(
        self,
        *,
        exposure_us: Optional[float] = None,
        line_time_us: Optional[float] = None,
        frame_rate_hz: Optional[float] = None,
        shutter: Optional[str] = None,
        roi: Union[None, str, Tuple[int, int, int, int]] = None,
        binning: Optional[int] = None,
        pixel_format: Optional[str] = None,
        trigger: Optional[str] = None,
        exposure_output_line: Optional[str] = None,
    ) -> Dict[str, Any]:
        """Apply the given settings (refused while streaming); returns what the
        device applied."""
    def applied_settings(self) -> Dict[str, Any]: ...
    def start(self) -> None: ...
    def stop(self) -> None: ...
    def software_trigger(self) -> None: ...
    def grab(self, timeout_ms: int = 5000) -> Frame:
        """The next frame (acquisition is started when needed)."""
    def frames(self, count: Optional[int] = None, timeout_ms: int = 5000) -> Iterator[Frame]:
        """The next count frames (None: until the stream ends)."""
    def calibration(self) -> Optional[Tuple[F32Array, Timing, Dict[str, Any]]]:
        """A simulated camera's PSF as recorded, Timing and capture description; None
        for other cameras."""
    def close(self) -> None: ...
    def __enter__(self) -> "Camera": ...
    def __exit__(self, *exc: Any) -> bool: ...

class LedController:
    """The LED pulse controller on a serial port, with the commands of `rollcam led`.
    A context manager. port None: the only USB serial port that looks like an
    Arduino. Errors: FileNotFoundError (no such port), PermissionError, TimeoutError
    (no reply), ValueError (a configuration the device refuses), OSError."""

    def __init__(
        self,
        port: Union[None, str, os.PathLike[str]] = None,
        *,
        baud: int = 115200,
        timeout_ms: int = 300,
        retries: int = 2,
        ready_ms: int = 2500,
    ) -> None: ...
    @property
    def port(self) -> str: ...
    def identify(self) -> Dict[str, Any]: ...
    def set(
        self,
        channel: int,
        period_us: int,
        *,
        duty: Optional[float] = None,
        width_us: Optional[int] = None,
        phase_us: int = 0,
        count: Optional[int] = None,
    ) -> Dict[str, Any]:
        """Configure and enable one channel; returns it as the controller reports it."""
    def off(self, channel: int) -> None: ...
    def arm(self, trigger: str = "sw") -> None:
        """sw, rise or fall."""
    def trigger(self) -> None: ...
    def stop(self) -> None: ...
    def status(self) -> Dict[str, Any]: ...
    def sync(self, trigger: str = "rise") -> Dict[str, Any]: ...
    def close(self) -> None: ...
    def __enter__(self) -> "LedController": ...
    def __exit__(self, *exc: Any) -> bool: ...

def led_ports() -> List[Dict[str, Any]]:
    """Serial ports on this machine: path, description, likely_controller."""

class LedEmulator:
    """A software LED controller on a pseudo-terminal reachable at the symlink `link`
    (as `rollcam led emulate`). A context manager; close() removes the link."""

    def __init__(self, link: Union[str, os.PathLike[str]]) -> None: ...
    @property
    def link(self) -> str: ...
    @property
    def target(self) -> str: ...
    def input_edge(self, rising: bool) -> bool:
        """An edge on the trigger input; True when it started the waveform."""
    def level_at(self, channel: int, t_us: int) -> bool:
        """Whether the channel's output is high t_us after the last trigger."""
    def close(self) -> None: ...
    def __enter__(self) -> "LedEmulator": ...
    def __exit__(self, *exc: Any) -> bool: ...
