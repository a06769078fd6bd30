"""rollcam from Python: a small scene through a synthetic diffuser, the imaging operator,
a reconstruction with a live trace, and one's own solver on the same operator.

Runs headless (`python examples/notebook.py`); each block is a notebook cell. Needs
the module (`pip install ./python`), NumPy and, for the last cell, SciPy.
"""

import numpy as np

import rollcam

# %% A PSF of a few bright spots (a caustic pattern in miniature) and the capture's timing.
rng = np.random.default_rng(0)
rows, cols = 32, 40
psf = np.zeros((rows, cols), np.float32)
for _ in range(8):
    psf[rng.integers(rows), rng.integers(cols)] += rng.uniform(0.5, 1.0)
psf /= psf.sum()
timing = rollcam.Timing(line_time_us=10.0, exposure_us=60.0, shutter="dual")

# %% The imaging operator: video (frames, rows, cols) -> one sensor image.
A = rollcam.ImagingOperator(psf, timing)
(frames, _, _), sensor = A.shape
print(f"{frames} frames of {rows} x {cols} in one {sensor[0]} x {sensor[1]} image, frame every {timing.frame_time_us} us")

# %% A bright square crossing the field, seen through the diffuser, with read noise.
truth = np.zeros(A.shape[0], np.float32)
for k in range(frames):
    c = 4 + k * (cols - 14) // max(frames - 1, 1)
    truth[k, 10:20, c : c + 8] = 100.0
raw = A.forward(truth) + rng.normal(0, 0.2, sensor).astype(np.float32)

# %% Reconstruct (FISTA with TV), watching the error fall.
def progress(row):
    if row["iteration"] % 25 == 0:
        print(f"  iteration {row['iteration']}: objective {row['objective']:.4g}, PSNR {row['psnr']:.2f} dB")


rec = rollcam.reconstruct(raw, psf, timing, iters=100, dark_level=0.0, truth=truth, callback=progress, cache=False)
print(f"rollcam: PSNR {rec.trace['psnr'][-1]:.2f} dB after {rec.summary['channels'][0]['iterations']} iterations")

# %% One's own solver on the same operator: least squares by SciPy (no prior).
try:
    from scipy.sparse.linalg import lsqr
except ImportError:
    lsqr = None
if lsqr is not None:
    x = lsqr(A.as_linear_operator(), raw.ravel().astype(np.float64), iter_lim=100)[0].reshape(truth.shape)
    mse = np.mean((x - truth) ** 2)
    print(f"lsqr: PSNR {10 * np.log10(truth.max() ** 2 / mse):.2f} dB (no TV prior)")

# %% The simulator and the analysis: a line of LEDs flashing square waves, seen through a
# synthetic diffuser, reconstructed, and each LED's flashing found in the spectrum.
sim = rollcam.simulate("led-array", rows=64, cols=80, leds=2, period_us=[1320.0, 1760.0], spacing_px=20.0, seed=1)
rec = rollcam.reconstruct(sim.raw, sim.psf, sim.timing, dark_level=sim.dark_level_adu, iters=40, cache=False)
a = rollcam.analyze(rec.video, sim.timing)
for r in a["regions"]:
    print(f"{r['name']}: peak at {r['peak_frequency_hz']:.0f} Hz (LEDs flash at {1e6 / 1320:.0f} and {1e6 / 1760:.0f} Hz)")

# %% The bench: a simulated camera, grabbed like a real one; its calibration reconstructs the frame.
with rollcam.Camera.open("sim:led-array") as cam:
    frame = cam.grab()
    psf_counts, cam_timing, cam_cfg = cam.calibration()
print(f"grabbed a {frame.pixels.shape} {frame.pixels.dtype} frame ({frame.status}), frame id {frame.meta['frame_id']}")
