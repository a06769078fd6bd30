"""The rollcam Python module against the library's own invariants and the CLI."""

import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

import rollcam

REPO = pathlib.Path(__file__).resolve().parents[2]


def small_problem(rows=24, cols=32, seed=1):
    """A PSF of a few bright spots, a moving square, and its noiseless raw image."""
    rng = np.random.default_rng(seed)
    psf = np.zeros((rows, cols), np.float32)
    for _ in range(6):
        psf[rng.integers(rows), rng.integers(cols)] += rng.uniform(0.5, 1.0)
    psf /= psf.sum()
    timing = rollcam.Timing(line_time_us=10.0, exposure_us=40.0, shutter="dual")
    op = rollcam.ImagingOperator(psf, timing)
    (k, m, n), _ = op.shape
    video = np.zeros((k, m, n), np.float32)
    for f in range(k):
        c = 4 + (f * (n - 12)) // max(k - 1, 1)
        video[f, 8:16, c : c + 6] = 100.0
    raw = op.forward(video)
    return psf, timing, op, video, raw


def test_timing_values_and_errors():
    t = rollcam.Timing(line_time_us=10.0, exposure_us=40.0, shutter="rolling", downsample=2, binning=3)
    assert (t.line_time_us, t.exposure_us, t.shutter, t.downsample, t.binning) == (10.0, 40.0, "rolling", 2, 3)
    assert t.frame_time_us == pytest.approx(60.0)
    w = t.weights(48)
    assert w.dtype == np.float32 and w.shape[0] == 24 and w.shape[1] == t.frames(48)
    with pytest.raises(ValueError, match="exposure_us"):
        rollcam.Timing(line_time_us=10.0, exposure_us=5.0)
    with pytest.raises(ValueError, match="line_time_us"):
        rollcam.Timing(line_time_us=-1.0, exposure_us=5.0)
    with pytest.raises(ValueError, match="unknown shutter mode 'sideways'"):
        rollcam.Timing(line_time_us=10.0, exposure_us=40.0, shutter="sideways")
    with pytest.raises(ValueError, match="downsample"):
        rollcam.Timing(line_time_us=10.0, exposure_us=40.0, downsample=0)


def test_operator_shapes_and_adjoint():
    psf, timing, op, video, raw = small_problem()
    (k, m, n), (sm, sn) = op.shape
    assert (m, n) == (sm, sn) == psf.shape
    assert k == timing.frames(psf.shape[0]) and k > 1
    assert raw.shape == (m, n) and raw.dtype == np.float32
    rng = np.random.default_rng(7)
    x = rng.standard_normal((k, m, n)).astype(np.float32)
    y = rng.standard_normal((m, n)).astype(np.float32)
    ax = op.forward(x)
    aty = op.adjoint(y)
    assert aty.shape == (k, m, n) and aty.dtype == np.float32
    lhs = float(np.dot(ax.ravel().astype(np.float64), y.ravel()))
    rhs = float(np.dot(x.ravel().astype(np.float64), aty.ravel()))
    assert abs(lhs - rhs) <= 1e-4 * max(abs(lhs), abs(rhs))
    # float64 and Fortran-ordered input is converted, not refused; flat input works.
    assert np.allclose(op.forward(np.asfortranarray(x.astype(np.float64))), ax, rtol=1e-5, atol=1e-6)
    assert np.allclose(op.forward(x.ravel()), ax)
    # Linearity: A(2x) = 2 Ax.
    assert np.allclose(op.forward(2 * x), 2 * ax, rtol=1e-5, atol=1e-5)


def test_lipschitz_bounds_every_rayleigh_quotient():
    psf, timing, op, video, raw = small_problem()
    lam = op.lipschitz()
    assert lam > 0
    rng = np.random.default_rng(3)
    for _ in range(5):
        x = rng.standard_normal(op.shape[0]).astype(np.float32)
        q = float(np.sum(op.forward(x).astype(np.float64) ** 2) / np.sum(x.astype(np.float64) ** 2))
        assert q <= lam * (1 + 1e-3)


def test_operator_errors():
    psf, timing, op, video, raw = small_problem()
    with pytest.raises(ValueError, match="entries"):
        op.forward(np.zeros(5, np.float32))
    with pytest.raises(ValueError, match="entries"):
        op.adjoint(np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match="psf"):
        rollcam.ImagingOperator(np.zeros((2, 3, 4), np.float32), timing)
    bad = psf.copy()
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        rollcam.ImagingOperator(bad, timing)
    with pytest.raises(ValueError, match="field of view .wide."):
        rollcam.ImagingOperator(psf, timing, fov="wide")


def test_linear_operator_with_scipy_lsqr():
    sla = pytest.importorskip("scipy.sparse.linalg")
    psf, timing, op, video, raw = small_problem(rows=16, cols=20)
    A = op.as_linear_operator()
    (k, m, n), _ = op.shape
    assert A.shape == (m * n, k * m * n)
    assert np.allclose(A.matvec(video.ravel()), raw.ravel())
    assert np.allclose(A.rmatvec(raw.ravel()), op.adjoint(raw).ravel())
    b = raw.ravel().astype(np.float64)
    result = sla.lsqr(A, b, iter_lim=60)
    x = result[0]
    assert result[1] in (1, 2, 7)  # converged, least squares, or the iteration limit
    residual = np.linalg.norm(A.matvec(x) - b)
    assert residual < 0.05 * np.linalg.norm(b)  # zero has residual ||b||
    # Better than the zero video at recovering the scene it came from.
    assert np.linalg.norm(x - video.ravel()) < np.linalg.norm(video.ravel())


def test_the_psf_has_its_own_dark_level():
    # A raw with a black offset of 100 counts beside a PSF recorded without one: the
    # raw's dark level alone would be taken off the PSF too and leave it all zero.
    psf, timing, op, video, raw = small_problem()
    scale = 100.0 / float(psf.max())
    offset = raw + 100.0
    with pytest.raises(ValueError, match="all zero after subtracting the dark level 100"):
        rollcam.reconstruct(offset, psf * scale, timing, iters=5, dark_level=100.0, cache=False)
    rec = rollcam.reconstruct(offset, psf * scale, timing, iters=30, obj_tol=0.0, dark_level=100.0, psf_dark_level=0.0, truth=video, cache=False)
    plain = rollcam.reconstruct(raw, psf, timing, iters=30, obj_tol=0.0, dark_level=0.0, truth=video, cache=False)
    assert rec.summary["psf_dark_level"] == 0.0
    # The scene comes back as well as from the capture without offsets.
    e, e0 = rec.summary["rel_error_scaled"], plain.summary["rel_error_scaled"]
    assert e < 1.2 * e0 + 0.02 and e < 0.9, (e, e0)
    with pytest.raises(ValueError, match="psf_dark_level = -1"):
        rollcam.reconstruct(offset, psf, timing, psf_dark_level=-1.0, cache=False)


def test_reconstruct_recovers_the_scene_and_reports():
    psf, timing, op, video, raw = small_problem()
    rec = rollcam.reconstruct(raw, psf, timing, iters=30, obj_tol=0.0, dark_level=0.0, truth=video, cache=False)
    assert rec.video.shape == video.shape and rec.video.dtype == np.float32
    t = rec.trace
    for key in ("seconds", "objective", "psnr", "rel_error", "iteration", "channel"):
        assert len(t[key]) == 30, key
    assert np.all(np.diff(t["seconds"]) >= 0)
    assert t["objective"][-1] < t["objective"][0]
    assert t["rel_error"][-1] < t["rel_error"][0]
    assert np.isfinite(t["psnr"]).all()
    s = rec.summary
    assert s["video_shape"] == [*video.shape, 1]
    assert s["channels"][0]["iterations"] == 30
    assert s["stopped"] is False and rec.stopped is False
    assert s["frame_time_us"] == pytest.approx(timing.frame_time_us)


def test_callback_sees_every_iteration_and_stops_the_solve():
    psf, timing, op, video, raw = small_problem()
    seen = []

    def callback(row):
        seen.append((row["iteration"], row["objective"]))
        return row["iteration"] >= 5

    rec = rollcam.reconstruct(raw, psf, timing, iters=50, dark_level=0.0, callback=callback, cache=False)
    assert rec.stopped and rec.summary["stopped"]
    iterations = rec.summary["channels"][0]["iterations"]
    assert iterations < 50
    assert [i for i, _ in seen] == list(range(1, len(seen) + 1))
    assert len(seen) == len(rec.trace["objective"]) == iterations
    assert np.allclose([o for _, o in seen], rec.trace["objective"])


def test_an_exception_in_the_callback_is_raised():
    psf, timing, op, video, raw = small_problem()

    def callback(row):
        raise RuntimeError("from the callback")

    with pytest.raises(RuntimeError, match="from the callback"):
        rollcam.reconstruct(raw, psf, timing, iters=20, dark_level=0.0, callback=callback, cache=False)


def test_reconstruct_errors():
    psf, timing, op, video, raw = small_problem()
    with pytest.raises(ValueError, match="tau_rel"):
        rollcam.reconstruct(raw, psf, timing, tau_rel=-1.0)
    with pytest.raises(ValueError, match="unknown solver|solver"):
        rollcam.reconstruct(raw, psf, timing, solver="newton")
    with pytest.raises(ValueError, match="psf"):
        rollcam.reconstruct(raw, psf[:10], timing, dark_level=0.0)
    with pytest.raises(ValueError, match="raw"):
        rollcam.reconstruct(np.zeros(7, np.float32), psf, timing)
    with pytest.raises(ValueError, match="truth"):
        rollcam.reconstruct(raw, psf, timing, dark_level=0.0, truth=video[:2], iters=2, cache=False)
    with pytest.raises(ValueError):
        rollcam.reconstruct(raw, psf, timing, scene={"support": [1, 2]})


def test_lenslet_psf():
    psf = rollcam.lenslet_psf(24, 32, seed=3)
    assert psf.shape == (24, 32) and psf.dtype == np.float32
    assert psf.min() >= 0 and psf.sum() == pytest.approx(1.0, rel=1e-4)
    assert np.array_equal(psf, rollcam.lenslet_psf(24, 32, seed=3))
    assert not np.array_equal(psf, rollcam.lenslet_psf(24, 32, seed=4))
    with pytest.raises(ValueError, match="lenslets"):
        rollcam.lenslet_psf(24, 32, lenslets=0)
    # A diffuser PSF gives a well-posed operator: the adjoint test holds on it too.
    op = rollcam.ImagingOperator(psf, rollcam.Timing(line_time_us=10.0, exposure_us=30.0))
    rng = np.random.default_rng(0)
    x = rng.random(op.shape[0], dtype=np.float32)
    y = rng.random(op.shape[1], dtype=np.float32)
    lhs, rhs = float(np.vdot(op.forward(x), y)), float(np.vdot(x, op.adjoint(y)))
    assert abs(lhs - rhs) <= 1e-4 * abs(lhs)


def write_capture(folder, text):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "capture.toml").write_text(text)
    return folder


def test_load_config_and_capture(tmp_path):
    folder = write_capture(
        tmp_path / "cap",
        'rows = 24\ncols = 32\nline_time_us = 12.5\nexposure_us = 50.0\nshutter = "rolling"\ndownsample = 2\n',
    )
    timing, cfg = rollcam.load_config(folder / "capture.toml")
    assert (timing.line_time_us, timing.exposure_us, timing.shutter, timing.downsample) == (12.5, 50.0, "rolling", 2)
    assert cfg["rows"] == 24 and cfg["cols"] == 32
    timing2, _ = rollcam.load_capture(folder)
    assert timing2 == timing
    with pytest.raises(FileNotFoundError, match="capture.toml"):
        rollcam.load_config(tmp_path / "missing" / "capture.toml")
    with pytest.raises(FileNotFoundError):
        rollcam.load_capture(tmp_path / "nowhere")
    with pytest.raises(OSError):
        rollcam.load_config(tmp_path)  # a folder, not a file
    bad = write_capture(tmp_path / "bad", "rows = 24\ncols = 32\nline_time_us = 10.0\nexposure_us = 50.0\nshutter = \"dual\"\nexposure = 3\n")
    with pytest.raises(ValueError, match="exposure"):
        rollcam.load_config(bad / "capture.toml")


def cli_command():
    for profile in ("debug", "release"):
        exe = REPO / "target" / profile / "rollcam"
        if exe.exists():
            return [str(exe)]
    if shutil.which("cargo"):
        return ["cargo", "run", "--quiet", "--manifest-path", str(REPO / "Cargo.toml"), "--bin", "rollcam", "--"]
    pytest.skip("no rollcam binary and no cargo to build one")


def test_reconstruct_equals_the_cli(tmp_path):
    psf, timing, op, video, raw = small_problem()
    raw = raw + np.random.default_rng(5).normal(0, 0.5, raw.shape).astype(np.float32)
    np.save(tmp_path / "raw.npy", raw.astype(np.float32))
    np.save(tmp_path / "psf.npy", psf.astype(np.float32))
    cache = tmp_path / "cache"
    env = dict(os.environ, ROLLCAM_CACHE_DIR=str(cache))
    out = tmp_path / "out"
    args = ["--tau-rel", "0.004", "--alpha", "3", "--iters", "25", "--solver", "fista"]
    subprocess.run(
        cli_command()
        + ["reconstruct", "--raw", str(tmp_path / "raw.npy"), "--psf", str(tmp_path / "psf.npy"), "--out", str(out)]
        + ["--line-time-us", "10", "--exposure-us", "40", "--shutter", "dual", "--dark-level", "0"]
        + args,
        check=True,
        env=env,
        cwd=REPO,
        stdout=subprocess.DEVNULL,
    )
    cli = np.load(out / "video.npy")
    old = os.environ.get("ROLLCAM_CACHE_DIR")
    os.environ["ROLLCAM_CACHE_DIR"] = str(cache)
    try:
        rec = rollcam.reconstruct(raw, psf, timing, tau_rel=0.004, alpha=3.0, iters=25, solver="fista", dark_level=0.0)
    finally:
        if old is None:
            del os.environ["ROLLCAM_CACHE_DIR"]
        else:
            os.environ["ROLLCAM_CACHE_DIR"] = old
    # video.npy drops the channel axis of a grey video, as the module does.
    assert cli.shape == rec.video.shape
    assert np.max(np.abs(cli - rec.video)) <= 1e-6 * max(1.0, float(np.max(np.abs(cli)))), np.max(np.abs(cli - rec.video))
    print("largest difference from the CLI:", float(np.max(np.abs(cli - rec.video))))
    import json

    summary = json.loads((out / "summary.json").read_text())
    assert summary["params"] == rec.summary["params"]
    assert summary["channels"][0]["iterations"] == rec.summary["channels"][0]["iterations"] <= 25
    assert summary["converged"] == rec.summary["converged"] == (rec.summary["channels"][0]["iterations"] < 25)


def test_the_example_notebook_runs_headless():
    script = REPO / "examples" / "notebook.py"
    env = dict(os.environ, MPLBACKEND="Agg")
    done = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "PSNR" in done.stdout


def test_still_start_is_the_default_and_zero_is_the_fallback():
    # A still square: the still image explains it, so the first video iterate from the
    # still start is far closer to the truth than the one from zero. (On the moving
    # square of small_problem it is not: nothing there is still.)
    psf, timing, op, moving, _ = small_problem()
    video = np.repeat(moving[:1], moving.shape[0], axis=0)
    raw = op.forward(video)
    still = rollcam.reconstruct(raw, psf, timing, iters=10, dark_level=0.0, truth=video, cache=False)
    zero = rollcam.reconstruct(raw, psf, timing, iters=10, dark_level=0.0, truth=video, cache=False, start="zero")
    start = still.summary["channels"][0]["start"]
    assert start["used"] is True and start["iterations"] > 0 and start["seconds"] > 0
    assert "start" not in zero.summary["channels"][0]
    # The trace's clock includes the still solve.
    assert still.trace["seconds"][0] >= start["seconds"]
    assert still.trace["rel_error"][0] < 0.5 * zero.trace["rel_error"][0]
    with pytest.raises(ValueError, match="auto, still or zero"):
        rollcam.reconstruct(raw, psf, timing, iters=1, dark_level=0.0, cache=False, start="cold")


def test_docstrings_and_signatures():
    assert "callback" in rollcam.reconstruct.__doc__
    assert "A^T b" in rollcam.ImagingOperator.adjoint.__doc__
    assert rollcam.ImagingOperator.__doc__ and rollcam.Timing.__doc__
    assert "line_time_us" in rollcam.Timing.__text_signature__
    stub = (REPO / "python" / "rollcam.pyi").read_text()
    names = ("Timing", "ImagingOperator", "Reconstruction", "reconstruct", "load_config", "load_capture", "lenslet_psf", "read_image")
    names += ("Simulation", "simulate", "analyze", "Camera", "Frame", "LedController", "LedEmulator", "led_ports", "SCENES", "FEATURES")
    for name in names:
        assert hasattr(rollcam, name) and name in stub, name
    # The stub's reconstruct() defaults are the module's (the command line's) constants.
    import re
    for key, const in (("iters", rollcam.DEFAULT_ITERS), ("obj_tol", rollcam.DEFAULT_OBJ_TOL)):
        m = re.search(rf"\n    {key}: [^=]+= ([0-9.e+-]+),", stub)
        assert m and float(m.group(1)) == pytest.approx(const, rel=1e-6), (key, m and m.group(1), const)
    assert '\n    tau_rel: Union[float, str] = "noise",' in stub


def test_tau_rel_auto_searches_a_still_scene_and_keeps_the_default_on_a_moving_one():
    # A still square: the held-out search runs and reports its ladder; the solve's tau
    # is the chosen tau_rel times max(A^T b). The moving square of small_problem: the
    # still image leaves the raw unexplained, no search, and the default's video.
    psf, timing, op, moving, _ = small_problem()
    video = np.repeat(moving[:1], moving.shape[0], axis=0)
    raw = op.forward(video)
    default = rollcam.reconstruct(raw, psf, timing, iters=20, dark_level=0.0, cache=False)
    auto = rollcam.reconstruct(raw, psf, timing, iters=20, dark_level=0.0, cache=False, tau_rel="auto")
    s = auto.summary["tau_search"]
    assert s["searched"] is True and len(s["candidates"]) >= 2 and s["held_out_pixels"] > 0
    best = min(s["candidates"], key=lambda c: c["held_out_residual"])
    assert best["tau_rel"] == pytest.approx(s["tau_rel"])
    choice = default.summary["params"]["tau_choice"]
    assert choice["rule"] == "noise" and choice["frames"] == moving.shape[0]
    # A noiseless video: the noise rule's weight is the video's floor, said.
    assert choice["tau_rel"] == pytest.approx(rollcam.VIDEO_TAU_REL_FLOOR) and choice["bounded"] is True
    assert s["candidates"][0]["tau_rel"] == pytest.approx(choice["tau_rel"])
    scale = default.summary["params"]["tau"] / choice["tau_rel"]
    assert auto.summary["params"]["tau"] == pytest.approx(s["tau_rel"] * scale, rel=1e-4)
    assert "tau_search" not in default.summary
    assert auto.trace["seconds"][0] >= s["seconds"]

    moving_raw = op.forward(moving)
    kept = rollcam.reconstruct(moving_raw, psf, timing, iters=20, dark_level=0.0, cache=False, tau_rel="auto")
    plain = rollcam.reconstruct(moving_raw, psf, timing, iters=20, dark_level=0.0, cache=False)
    assert kept.summary["tau_search"]["searched"] is False
    assert np.array_equal(kept.video, plain.video)
    with pytest.raises(ValueError, match="expected a number .* noise or auto"):
        rollcam.reconstruct(raw, psf, timing, iters=1, dark_level=0.0, cache=False, tau_rel="often")
    with pytest.raises(ValueError, match="tau"):
        rollcam.reconstruct(raw, psf, timing, iters=1, dark_level=0.0, cache=False, tau=0.1, tau_rel="auto")


def test_tau_rel_auto_on_three_channels_holds_out_pixels_of_each():
    # The search sums the held-out residual over the channels, which share one tau.
    psf, timing, op, moving, _ = small_problem()
    video = np.repeat(moving[:1], moving.shape[0], axis=0)
    raw = op.forward(video)
    raw2 = np.stack([raw, 0.5 * raw, 0.25 * raw], axis=-1)
    psf2 = np.stack([psf, psf, psf], axis=-1)
    one = rollcam.reconstruct(raw, psf, timing, iters=10, dark_level=0.0, cache=False, tau_rel="auto")
    two = rollcam.reconstruct(raw2, psf2, timing, iters=10, dark_level=0.0, cache=False, tau_rel="auto")
    s1, s2 = one.summary["tau_search"], two.summary["tau_search"]
    assert s2["searched"] is True
    assert s2["held_out_pixels"] == 3 * s1["held_out_pixels"]
    assert two.video.shape[-1] == 3 and np.all(np.isfinite(two.video))
    assert len(two.summary["channels"]) == 3
