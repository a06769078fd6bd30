"""Video from one rolling-shutter photograph taken through a diffuser.

Arrays go in as anything NumPy converts to float32 (converted once to a C-contiguous
float32 array when they are not one) and come out as new float32 arrays. The GIL is
released while the operator runs and while a reconstruction solves. Invalid values
raise ValueError, file errors OSError (FileNotFoundError for a missing file), with
the messages of the command-line tool.
"""

import os
from typing import Any, Callable, Dict, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
SHUTTER_MODES: list[str]
"""The shutter modes a Timing takes: global, rolling, dual, dual-center-out."""

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
    psf: ArrayLike,
    timing: Timing,
    *,
    tau: Optional[float] = None,
    tau_rel: float = 2e-3,
    alpha: float = 5.0,
    solver: Optional[str] = None,
    iters: int = 200,
    rel_tol: float = 0.0,
    obj_tol: float = 0.0,
    time_budget_s: Optional[float] = None,
    tv_prox: str = "auto",
    fov: str = "sensor",
    dark_level: Optional[float] = None,
    saturation_level: Optional[float] = None,
    scene: Optional[Dict[str, Any]] = None,
    truth: Optional[ArrayLike] = None,
    callback: Optional[Callable[[Dict[str, Any]], Optional[bool]]] = None,
    cache: Union[None, bool, str, os.PathLike[str]] = None,
) -> Reconstruction:
    """Reconstruct a video from one raw capture (rows, cols[, channels]) and its PSF
    (same size), as `rollcam reconstruct` does with the same values.

    tau: absolute TV weight (default: tau_rel times max(A^T b)); alpha: temporal TV
    weight relative to the spatial ones; solver: fista, fista-restart (default),
    mfista, admm or pgd; dark_level: black offset (estimated when None);
    scene: the [scene] keys of capture.toml (support, frames, static, ...);
    truth: video (frames, rows, cols[, channels]) for PSNR in the trace;
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
