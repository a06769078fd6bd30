"""rollcam.simulate, rollcam.analyze, the cameras and the LED controller from Python,
against the command-line tool on the same inputs and against the emulator's own state."""

import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

import rollcam

from test_rollcam import REPO, cli_command

FIXTURE = REPO / "fixtures" / "captures" / "led-505hz"


def run_cli(args, **kw):
    return subprocess.run(cli_command() + args, check=True, cwd=REPO, capture_output=True, text=True, **kw)


# --- simulate -----------------------------------------------------------------


def test_simulate_equals_the_cli(tmp_path):
    out = tmp_path / "sim"
    run_cli(["simulate", "--out", str(out), "--rows", "48", "--cols", "64", "--seed", "3", "--period-us", "1320"])
    s = rollcam.simulate(rows=48, cols=64, seed=3, period_us=[1320.0])
    truth = np.load(out / "truth.npy")  # a grey video: (frames, rows, cols)
    assert np.array_equal(truth, s.truth)
    # raw.tiff holds the same integer counts.
    assert np.array_equal(rollcam.read_image(out / "raw.tiff"), s.raw)
    assert s.raw.shape == (48, 64) and s.raw.dtype == np.float32
    assert np.allclose(rollcam.read_image(out / "psf.tiff"), np.round(s.psf), atol=0.5)
    timing, cfg = rollcam.load_capture(out)
    assert timing == s.timing
    assert cfg["dark_level"] == s.config["dark_level"] == s.dark_level_adu
    assert s.truth.shape[0] == s.timing.frames(48)
    assert s.frame_time_us == pytest.approx(s.timing.frame_time_us)


def test_simulate_then_reconstruct_finds_the_disc():
    s = rollcam.simulate("moving-disc", rows=48, cols=64, seed=2, disc_radius_px=4.0, disc_px_per_ms=6.0)
    rec = rollcam.reconstruct(s.raw, s.psf, s.timing, dark_level=s.dark_level_adu, iters=60, truth=s.truth, cache=False)
    assert rec.video.shape == s.truth.shape
    err = rec.trace["rel_error"][-1]
    assert np.isfinite(err) and err < 0.8, err
    # The disc's brightest pixel in the middle frame is near the truth's.
    k = s.truth.shape[0] // 2
    t = np.unravel_index(np.argmax(s.truth[k]), s.truth[k].shape)
    r = np.unravel_index(np.argmax(rec.video[k]), rec.video[k].shape)
    assert np.hypot(t[0] - r[0], t[1] - r[1]) <= 6.0, (t, r)


def test_simulate_scenes_and_errors():
    assert set(rollcam.SCENES) == {"led-array", "moving-disc", "disc-over-texture", "occluder", "stack"}
    stack = np.zeros((3, 24, 32), np.float32)
    stack[1, 10:14, 10:14] = 50.0
    s = rollcam.simulate("stack", stack=stack, rows=24, cols=32, stack_interval_us=500.0, noise=False)
    assert s.truth.max() > 0 and s.truth.shape[1:] == (24, 32)
    psf = rollcam.lenslet_psf(24, 32, seed=4)
    s2 = rollcam.simulate("led-array", psf=psf * 1000 + 5, leds=2, period_us=[1320.0], noise=False)
    assert s2.raw.shape == (24, 32)
    with pytest.raises(ValueError, match="unknown field `colour`"):
        rollcam.simulate(colour=3)
    with pytest.raises(ValueError, match="unknown scene 'spiral'"):
        rollcam.simulate("spiral")
    with pytest.raises(ValueError, match="stack"):
        rollcam.simulate("stack", rows=24, cols=32)
    with pytest.raises(ValueError, match="scene is 24 x 32 pixels"):
        rollcam.simulate("stack", stack=stack, rows=48, cols=64)
    with pytest.raises(ValueError, match="rows = 0"):
        rollcam.simulate(rows=0)
    with pytest.raises(ValueError, match="exposure_us"):
        rollcam.simulate(exposure_us=-1.0)
    bad = stack.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        rollcam.simulate("stack", stack=bad, rows=24, cols=32)


# --- analyze ------------------------------------------------------------------


def test_analyze_equals_the_cli(tmp_path):
    out = tmp_path / "sim"
    run_cli(["simulate", "--out", str(out), "--rows", "96", "--cols", "64", "--seed", "5", "--leds", "2", "--period-us", "1320,1760", "--no-noise"])
    analysis = tmp_path / "analysis"
    run_cli(["analyze", "--video", str(out / "truth.npy"), "--config", str(out / "capture.toml"), "--out", str(analysis), "--waveform-period-us", "1320"])
    cli = json.loads((analysis / "analysis.json").read_text())
    timing, _ = rollcam.load_capture(out)
    a = rollcam.analyze(np.load(out / "truth.npy"), timing, waveform_period_us=1320.0)
    assert a["video_shape"] == cli["video_shape"]
    assert a["theory"]["frame_time_us"] == pytest.approx(cli["theory"]["frame_time_us"])
    assert len(a["regions"]) == len(cli["regions"]) >= 2
    for mine, theirs in zip(a["regions"], cli["regions"]):
        assert mine["region"] == theirs["region"]
        assert mine["temporal_contrast"] == pytest.approx(theirs["temporal_contrast"], rel=1e-9)
        assert mine["peak_frequency_hz"] == pytest.approx(theirs["peak_frequency_hz"], rel=1e-9)
        course = mine["course"]
        assert course.shape == (a["video_shape"][0],)
        assert mine["frequency_hz"].shape == mine["power"].shape
        # The course is the region's sum over the (untrimmed) video.
        r = mine["region"]
        v = np.load(out / "truth.npy")[:, r["r0"] : r["r1"], r["c0"] : r["c1"]]
        assert np.allclose(course, v.sum(axis=(1, 2), dtype=np.float64), rtol=1e-5)
    # An LED flashing every 1320 us is found at 1e6 / 1320 Hz within a spectral bin.
    peaks = [r["peak_frequency_hz"] for r in a["regions"]]
    assert any(abs(p - 1e6 / 1320.0) <= a["bin_hz"] for p in peaks), peaks
    with pytest.raises(ValueError, match="at least 4"):
        rollcam.analyze(np.zeros((2, 8, 8), np.float32), timing)
    with pytest.raises(ValueError, match="distance_mm and pixel_pitch_um"):
        rollcam.analyze(np.load(out / "truth.npy"), timing, distance_mm=5.0)
    with pytest.raises(ValueError, match="region"):
        rollcam.analyze(np.load(out / "truth.npy"), timing, regions=[(1, 2, 3)])


# --- cameras ------------------------------------------------------------------


def test_simulated_camera_grabs_frames_that_reconstruct():
    with rollcam.Camera.open("sim:led-array") as cam:
        assert cam.info()["backend"] == "sim"
        g = cam.geometry()
        applied = cam.configure(exposure_us=660.0, line_time_us=220.0, shutter="dual")
        assert applied["exposure_us"] == pytest.approx(660.0)
        frames = list(cam.frames(3))
        assert [f.meta["sequence"] for f in frames] == [0, 1, 2]
        for f in frames:
            assert f.status == "complete"
            assert f.pixels.shape == (g["height"], g["width"]) and f.pixels.dtype == np.uint16
        psf, timing, cfg = cam.calibration()
        assert psf.shape == frames[0].pixels.shape
        assert (timing.line_time_us, timing.exposure_us, timing.shutter) == (220.0, 660.0, "dual")
        rec = rollcam.reconstruct(frames[0].pixels, psf, timing, dark_level=cfg["dark_level"], iters=10, cache=False)
        assert rec.video.shape[0] == timing.frames(psf.shape[0]) and np.isfinite(rec.video).all()
        with pytest.raises(ValueError, match="out of range"):
            cam.stop()
            cam.configure(exposure_us=1e-3)
    with pytest.raises(ValueError, match="closed"):
        cam.grab()


def test_replay_camera_gives_the_recorded_frames():
    with rollcam.Camera.open(f"replay:{FIXTURE}") as cam:
        frames = list(cam.frames())
    assert len(frames) == 3
    for i, f in enumerate(frames):
        assert np.array_equal(f.pixels.astype(np.float32), rollcam.read_image(FIXTURE / f"frame_{i:06d}.tiff"))
    with rollcam.Camera.open(f"replay:{FIXTURE}") as cam:
        for _ in range(3):
            cam.grab()
        with pytest.raises(EOFError, match="end of stream"):
            cam.grab()


def test_camera_errors():
    with pytest.raises(ValueError, match="expected backend:id"):
        rollcam.Camera.open("nonsense")
    with pytest.raises(ValueError, match="unknown simulated scene"):
        rollcam.Camera.open("sim:spiral")
    with pytest.raises(OSError):
        rollcam.Camera.open("replay:/no/such/capture")


@pytest.mark.skipif("aravis" not in rollcam.FEATURES, reason="built without the aravis feature")
def test_aravis_fake_camera():
    with rollcam.Camera.open("aravis:Fake_1") as cam:
        assert cam.info()["backend"] == "aravis"
        applied = cam.configure(exposure_us=2000.0, roi=(0, 0, 64, 48), pixel_format="Mono16")
        assert applied["roi"] == {"x": 0, "y": 0, "width": 64, "height": 48}
        f = cam.grab(timeout_ms=5000)
        assert f.status == "complete" and f.pixels.shape == (48, 64)
        assert f.meta["settings"]["exposure_us"] == pytest.approx(2000.0)
        assert cam.calibration() is None
        cam.stop()
        with pytest.raises(ValueError, match="out of range"):
            cam.configure(exposure_us=1e12)
    with pytest.raises(FileNotFoundError, match="not found"):
        rollcam.Camera.open("aravis:Fake_does_not_exist")


# --- the LED controller ---------------------------------------------------------


def test_led_controller_against_the_emulator(tmp_path):
    link = tmp_path / "led"
    with rollcam.LedEmulator(link) as emu:
        assert pathlib.Path(link).is_symlink()
        with rollcam.LedController(link, ready_ms=2000) as ctl:
            info = ctl.identify()
            assert info["name"] == "rollcam-led" and info["channels"] == 4
            report = ctl.set(0, 1000, duty=0.25)
            assert report["config"]["period_us"] == 1000 and report["config"]["width_us"] == 250
            ctl.set(1, 2000, width_us=100, phase_us=50, count=3)
            ctl.arm("rise")
            assert emu.input_edge(True)
            assert emu.level_at(0, 100) and not emu.level_at(0, 300)
            assert not emu.level_at(1, 20) and emu.level_at(1, 100)
            st = ctl.status()
            assert st["status"]["state"] == "running" and st["status"]["enabled"][:2] == [True, True]
            sync = ctl.sync("rise")
            assert sync["channels"][0]["period_us"] == 1000
            ctl.stop()
            ctl.off(1)
            assert ctl.status()["status"]["enabled"][1] is False
            with pytest.raises(ValueError, match="period_us"):
                ctl.set(0, 10)
            with pytest.raises(ValueError, match="duty"):
                ctl.set(0, 1000, duty=1.5)
            with pytest.raises(ValueError, match="expected sw, rise or fall"):
                ctl.arm("sideways")
        # The CLI on the same emulator says the same.
        cli = json.loads(run_cli(["led", "--port", str(link), "--json", "identify"]).stdout)
        assert cli == info
    assert not os.path.lexists(link)
    with pytest.raises(FileNotFoundError, match="not found"):
        rollcam.LedController(tmp_path / "nothing", ready_ms=0)


# --- a bench calibration ---------------------------------------------------------


def test_reconstruct_with_a_calibration_equals_the_cli(tmp_path):
    out = tmp_path / "bench"
    run_cli(["simulate", "--out", str(out), "--rows", "48", "--cols", "64", "--seed", "4", "--sensor-defects", "--calibration-shots", "3"])
    shots = out / "calibration-shots"
    cal = tmp_path / "cal"
    psf_shots = sorted(str(p) for p in (shots / "psf").iterdir())
    run_cli(["calibrate", "--dark", str(shots / "dark"), "--psf-shots", *psf_shots, "--out", str(cal)])
    rec_dir = tmp_path / "rec"
    cache = tmp_path / "cache"
    env = dict(os.environ, ROLLCAM_CACHE_DIR=str(cache))
    flags = ["--iters", "15", "--solver", "fista", "--tau-rel", "0.003"]
    run_cli(["reconstruct", "--raw", str(out / "raw.tiff"), "--calibration", str(cal), "--config", str(out / "capture.toml"), "--out", str(rec_dir)] + flags, env=env)
    cli = np.load(rec_dir / "video.npy")
    timing, cfg = rollcam.load_capture(out)
    raw = rollcam.read_image(out / "raw.tiff").astype(np.uint16)  # a 16-bit raw, as the TIFF
    rec = rollcam.reconstruct(raw, None, timing, calibration=cal, dark_level=cfg.get("dark_level"), iters=15, solver="fista", tau_rel=0.003, cache=cache)
    assert rec.video.shape == cli.shape
    assert np.max(np.abs(cli - rec.video)) <= 1e-6 * max(1.0, float(np.max(np.abs(cli))))
    summary = json.loads((rec_dir / "summary.json").read_text())
    assert rec.summary["inputs"]["calibration"] == summary["inputs"]["calibration"] == str(cal)
    assert rec.summary["inputs"]["psf"] == summary["inputs"]["psf"]
    # The fit report reaches Python as summary.json holds it: its figures, its
    # warnings and the terminal's line.
    fit, cli_fit = rec.summary["fit"], summary["fit"]
    for key in ("chi2_video", "chi2_still", "motion_explained", "warnings", "line", "noise", "psf_orientation"):
        assert key in fit and key in cli_fit, key
    # The PSF orientation check: the given PSF and its three flips, each a finite chi2.
    flips = {f["flip"]: f["chi2"] for f in fit["psf_orientation"]["flips"]}
    assert set(flips) == {"upside-down", "left-right", "rotated180"}, flips
    assert all(0 < c < float("inf") for c in flips.values()), flips
    assert isinstance(fit["warnings"], list) and fit["line"].startswith("fit: chi2")
    assert 0 < fit["chi2_video"] < float("inf") and 0 < fit["chi2_still"] < float("inf")
    # The plan reaches Python as the command line decided it: the same mode and weight.
    plan, cli_plan = rec.summary["plan"], summary["plan"]
    assert plan["mode"] == cli_plan["mode"] and plan["mode"] in ("whole-grid", "sparse-sources", "static-dynamic", "key-frames", "declared")
    assert plan["tau"] == cli_plan["tau"] and plan["processes"] == {"kind": "one"}
    if fit["noise"] == cli_fit["noise"]:
        assert fit["chi2_video"] == pytest.approx(cli_fit["chi2_video"], rel=1e-3)
        assert fit["warnings"] == cli_fit["warnings"]
    with pytest.raises(ValueError, match="no PSF"):
        rollcam.reconstruct(raw, None, timing)
    with pytest.raises(FileNotFoundError, match="expected a calibration folder"):
        rollcam.reconstruct(raw, None, timing, calibration=tmp_path / "no-such-calibration")


def test_reconstruct_with_key_frames_equals_the_cli(tmp_path):
    out = tmp_path / "sim"
    run_cli(["simulate", "--out", str(out), "--scene", "disc-over-texture", "--rows", "48", "--cols", "64", "--seed", "5", "--keyframes", "first,last"])
    timing, cfg = rollcam.load_capture(out)
    tables = cfg["keyframes"]
    assert len(tables) == 2 and tables[0]["start_us"] == 0.0
    rec_dir = tmp_path / "rec"
    cache = tmp_path / "cache"
    env = dict(os.environ, ROLLCAM_CACHE_DIR=str(cache))
    run_cli(["reconstruct", "--raw", str(out / "raw.tiff"), "--psf", str(out / "psf.tiff"), "--config", str(out / "capture.toml"), "--out", str(rec_dir), "--iters", "20"], env=env)
    cli = np.load(rec_dir / "video.npy")
    raw = rollcam.read_image(out / "raw.tiff").astype(np.uint16)
    psf = rollcam.read_image(out / "psf.tiff")
    # Each table with its image in place of its file (16-bit, as the TIFF).
    keys = [dict(t, image=rollcam.read_image(out / t["file"]).astype(np.uint16)) for t in tables]
    rec = rollcam.reconstruct(raw, psf, timing, dark_level=cfg.get("dark_level"), saturation_level=cfg.get("saturation_level"), keyframes=keys, iters=20, cache=cache)
    assert rec.video.shape == cli.shape
    assert np.max(np.abs(cli - rec.video)) <= 1e-5 * max(1.0, float(np.max(np.abs(cli))))
    fit = rec.summary["channels"][0]["keyframes"]
    assert len(fit) == 2 and fit[0]["gain_from"] == "fitted" and fit[0]["gain"] > 0
    # The model follows the share of the grid the key frames show changing: the static +
    # dynamic model for a small moving part, else the departure from their
    # interpolation (docs/keyframes.md); the scene can ask for either.
    share = rec.summary["plan"]["keyframe_moving_share"]
    assert (rec.summary.get("static_background") is not None) == (share < 0.05)
    assert fit[0]["stiffness_cap"] == (1.0 if share < 0.05 else 10.0)
    rec = rollcam.reconstruct(raw, psf, timing, dark_level=cfg.get("dark_level"), saturation_level=cfg.get("saturation_level"), keyframes=keys, iters=20, cache=cache, scene={"static_background": True})
    assert rec.summary.get("static_background") is not None
    assert rec.summary["channels"][0]["keyframes"][0]["stiffness_cap"] == 1.0
    keyed_plain = rollcam.reconstruct(raw, psf, timing, dark_level=cfg.get("dark_level"), saturation_level=cfg.get("saturation_level"), keyframes=keys, iters=20, cache=cache, scene={"static_background": False})
    assert keyed_plain.summary.get("static_background") is None
    assert keyed_plain.summary["channels"][0]["keyframes"][0]["stiffness_cap"] == 10.0
    assert np.max(np.abs(keyed_plain.video - rec.video)) > 1e-3 * float(np.max(np.abs(cli)))
    # Without them the video differs: the key frames reached the solve.
    plain = rollcam.reconstruct(raw, psf, timing, dark_level=cfg.get("dark_level"), saturation_level=cfg.get("saturation_level"), iters=20, cache=cache)
    assert np.max(np.abs(plain.video - rec.video)) > 1e-3 * float(np.max(np.abs(cli)))
    with pytest.raises(ValueError, match=r"keyframes\[0\]: expected an image"):
        rollcam.reconstruct(raw, psf, timing, keyframes=[{"start_us": 0.0, "exposure_us": 10.0}])
    with pytest.raises(ValueError, match="keyframes.exposure_us"):
        rollcam.reconstruct(raw, psf, timing, keyframes=[dict(keys[0], exposure_us=-1.0)])
