//! Hostile and careless command lines: nothing is overwritten, sizes are checked before
//! they are allocated, values are checked before they are used. Every input file is
//! byte-identical after a refused run.

use crate::support::cli;
use cli::{fails, ok, rollcam, rollcam_env};
use std::path::{Path, PathBuf};

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

/// Every file under `dir` with its bytes, to compare before and after a run.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((p.clone(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

/// A small simulated capture in `dir/sim`: (raw, psf, config).
fn simulated(dir: &Path) -> (String, String, String) {
    let sim = dir.join("sim");
    ok(&rollcam(&["simulate", "--rows", "32", "--cols", "40", "--spacing-px", "6", "--out", &s(&sim)], dir));
    (s(&sim.join("raw.tiff")), s(&sim.join("psf.tiff")), s(&sim.join("capture.toml")))
}

#[test]
fn reconstruct_never_overwrites_a_raw_named_like_its_output() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    // The raw is called video.tiff, in the folder given as --out.
    let d = dir.path().join("d");
    std::fs::create_dir(&d).unwrap();
    std::fs::copy(&raw, d.join("video.tiff")).unwrap();
    let raw_in_d = s(&d.join("video.tiff"));
    let before = snapshot(&d);
    let args = ["reconstruct", "--raw", &raw_in_d, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &s(&d)];
    let e = fails(&rollcam(&args, dir.path()));
    assert!(e.contains("not empty") && e.contains("video.tiff") && e.contains("--force"), "{e}");
    let mut forced = args.to_vec();
    forced.push("--force");
    let e = fails(&rollcam(&forced, dir.path()));
    assert!(e.contains("video.tiff") && e.contains("the raw image (--raw)") && e.contains("never overwritten"), "{e}");
    assert_eq!(snapshot(&d), before, "the folder holding the raw is untouched");
}

#[test]
fn force_writes_the_commands_files_and_leaves_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let d = dir.path().join("rec");
    std::fs::create_dir(&d).unwrap();
    std::fs::write(d.join("notes.txt"), "lab notes").unwrap();
    let args = ["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &s(&d), "--force"];
    ok(&rollcam(&args, dir.path()));
    assert_eq!(std::fs::read_to_string(d.join("notes.txt")).unwrap(), "lab notes");
    assert!(d.join("summary.json").is_file() && d.join("video.npy").is_file());
    // Run again with --force: the earlier run's files are replaced, the notes stay.
    ok(&rollcam(&args, dir.path()));
    assert_eq!(std::fs::read_to_string(d.join("notes.txt")).unwrap(), "lab notes");
}

#[test]
fn simulate_refuses_an_existing_capture_folder() {
    let dir = tempfile::tempdir().unwrap();
    let _ = simulated(dir.path());
    let sim = dir.path().join("sim");
    let before = snapshot(&sim);
    let e = fails(&rollcam(&["simulate", "--rows", "32", "--cols", "40", "--seed", "7", "--out", &s(&sim)], dir.path()));
    assert!(e.contains("not empty") && e.contains("psf.tiff"), "{e}");
    assert_eq!(snapshot(&sim), before);
}

#[test]
fn capture_refuses_a_folder_holding_a_psf() {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    std::fs::create_dir(&cap).unwrap();
    std::fs::write(cap.join("psf.tiff"), b"the bench's measured PSF").unwrap();
    let before = snapshot(&cap);
    let e = fails(&rollcam(&["capture", "--camera", "sim:led-array", "--frames", "1", "--out", &s(&cap)], dir.path()));
    assert!(e.contains("not empty") && e.contains("psf.tiff"), "{e}");
    assert_eq!(snapshot(&cap), before);
}

#[test]
fn a_bad_output_folder_is_refused_before_any_input_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "x").unwrap();
    // The raw does not exist either: the output folder is the first thing checked.
    let e = fails(&rollcam(
        &["reconstruct", "--raw", "missing.tiff", "--psf", "missing.tiff", "--line-time-us", "10", "--exposure-us", "100", "--out", &s(&file.join("rec"))],
        dir.path(),
    ));
    assert!(e.contains("a-file/rec") && e.contains("cannot create the folder"), "{e}");
    assert!(!e.contains("missing.tiff"), "{e}");
    let e = fails(&rollcam(
        &["reconstruct", "--raw", "missing.tiff", "--psf", "missing.tiff", "--line-time-us", "10", "--exposure-us", "100", "--out", &s(&file)],
        dir.path(),
    ));
    assert!(e.contains("not a folder"), "{e}");
}

#[test]
fn the_lipschitz_upper_bound_holds_on_every_shutter_and_grid() {
    use rollcam::model::capture::Fov;
    use rollcam::model::op::{pseudo_random, Operator};
    use rollcam::model::rolling::RollingShutterModel;
    use rollcam::model::scene::Restricted;
    use rollcam::model::shutter::{ShutterMode, Timing};
    use rollcam::model::static_dynamic::StaticPlusDynamic;
    use rollcam::solve::lipschitz::power_iteration;
    let (m, n) = (24, 20);
    for (seed, mode) in ShutterMode::ALL.into_iter().enumerate() {
        for fov in [Fov::Sensor, Fov::Full] {
            // A diffuser-like PSF (positive, spread over the sensor) and one with
            // negative values (a background-subtracted PSF).
            for signed in [false, true] {
                let psf: Vec<f32> = pseudo_random(m * n, seed as u64 + 3).iter().map(|v| if signed { v - 0.3 } else { (v + 0.5).powi(4) }).collect();
                let w = Timing::new(m, 10.0, 35.0, mode).weights().unwrap();
                let model = RollingShutterModel::of_psf(&psf, m, n, fov, w);
                let (_, mv, nv) = model.video_shape();
                let still = Restricted::new(&model, 0..mv, 0..nv, true);
                let both = StaticPlusDynamic::new(&model, [0.3, 1.7]);
                let ops: [(&str, &dyn Operator); 3] = [("video", &model), ("static", &still), ("static + dynamic", &both)];
                for (what, op) in ops {
                    let lambda = power_iteration(op, 2000, 1e-10, 7).lambda_max;
                    let bound = op.lipschitz_upper_bound().unwrap();
                    let case = format!("{mode:?} {fov:?} signed {signed} {what}");
                    assert!(lambda <= bound * (1.0 + 1e-4), "{case}: lambda {lambda} above the bound {bound}");
                    // Tight enough to catch a stored constant 10 times too large (the
                    // probe's 2.9 for 0.297) on a diffuser's PSF.
                    if !signed {
                        assert!(bound < 5.0 * lambda, "{case}: the bound {bound} is too loose to catch a wrong value ({lambda})");
                    }
                }
            }
        }
    }
}

#[test]
fn a_wrong_cached_lipschitz_constant_is_measured_again() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let cache = dir.path().join("cache");
    let run = |out: &str| {
        let o = rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "20", "--out", out], &cache);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (rollcam::io::read_npy(Path::new(out).join("video.npy")).unwrap(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let (reference, _) = run(&s(&dir.path().join("rec0")));
    let entries: Vec<PathBuf> = std::fs::read_dir(cache.join("lipschitz")).unwrap().map(|e| e.unwrap().path()).collect();
    assert!(!entries.is_empty());
    let read = |e: &Path| -> serde_json::Map<String, serde_json::Value> {
        serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(e).unwrap()).unwrap().as_object().unwrap().clone()
    };
    let measured: Vec<f64> = entries.iter().map(|e| read(e)["lambda_max"].as_f64().unwrap()).collect();
    // Corrupt values, and the probe's mistake: a constant 10 times too large (steps 10
    // times too short, a worse video within the same iterations) or too small.
    let cases: [(&str, &dyn Fn(f64) -> serde_json::Value); 6] = [
        ("1e-12", &|_| serde_json::json!(1e-12)),
        ("1e300", &|_| serde_json::json!(1e300)),
        ("-3", &|_| serde_json::json!(-3)),
        ("0", &|_| serde_json::json!(0)),
        ("10 times the measured value", &|l| serde_json::json!(10.0 * l)),
        ("a tenth of the measured value", &|l| serde_json::json!(0.1 * l)),
    ];
    for (i, (bad, value)) in cases.iter().enumerate() {
        for (e, &l) in entries.iter().zip(&measured) {
            let mut v = read(e);
            v.insert("lambda_max".into(), value(l));
            std::fs::write(e, serde_json::to_string(&v).unwrap()).unwrap();
        }
        let (video, stderr) = run(&s(&dir.path().join(format!("rec{}", i + 1))));
        assert!(video.iter().all(|x| x.is_finite()));
        assert_eq!(video, reference, "cache entry {bad}: the video differs from the measured constant's");
        assert!(stderr.contains("measured again"), "{bad}: {stderr}");
        // The entry is overwritten with the measured value.
        for (e, &l) in entries.iter().zip(&measured) {
            assert_eq!(read(e)["lambda_max"].as_f64().unwrap(), l, "{bad}: the entry was not measured again");
        }
    }
    // A correct entry is used as it is: no warning, no measurement.
    let (video, stderr) = run(&s(&dir.path().join("rec-cached")));
    assert_eq!(video, reference);
    assert!(!stderr.contains("measured again") && !stderr.contains("measured Lipschitz constant"), "{stderr}");
}

/// `capture.toml` with `key = value` replaced (or added).
fn config_with(dir: &Path, cfg: &str, name: &str, key: &str, value: &str) -> String {
    let text = std::fs::read_to_string(cfg).unwrap();
    let mut lines: Vec<String> = text.lines().filter(|l| !l.starts_with(&format!("{key} ="))).map(String::from).collect();
    lines.insert(0, format!("{key} = {value}"));
    let p = dir.join(name);
    std::fs::write(&p, lines.join("\n")).unwrap();
    s(&p)
}

#[test]
fn sizes_from_capture_toml_are_checked_before_anything_is_allocated() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let run = |config: &str, limit: Option<&str>| {
        let env: Vec<(&str, &str)> = limit.map(|l| ("ROLLCAM_MEMORY_LIMIT_GB", l)).into_iter().collect();
        let never = s(&dir.path().join("never"));
        let o =
            rollcam_env(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", config, "--iters", "2", "--out", &never], &dir.path().join("cache"), &env);
        assert!(!o.status.success());
        assert!(o.status.code().is_some(), "killed by a signal (an abort): {o:?}");
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    // Used to panic ("capacity overflow") building the row table before validation.
    let e = run(&config_with(dir.path(), &cfg, "max.toml", "rows", "9223372036854775807"), None);
    assert!(e.contains("max.toml") && e.contains("rows") && e.contains("at most 65536"), "{e}");
    let e = run(&config_with(dir.path(), &cfg, "big.toml", "rows", "200000000"), None);
    assert!(e.contains("rows") && e.contains("at most 65536"), "{e}");
    let e = run(&config_with(dir.path(), &cfg, "cols.toml", "cols", "200000000"), None);
    assert!(e.contains("cols") && e.contains("at most 65536"), "{e}");
    // An exposure typed in ns: refused as a likely unit mistake (3e7 on 32 rows of
    // 220 us gave 136387 frames that fit the memory) ...
    for ns in ["3e9", "3e7"] {
        let e = run(&config_with(dir.path(), &cfg, "ns.toml", "exposure_us", ns), None);
        assert!(e.contains("exposure_us") && e.contains("readout") && e.contains("ns"), "{e}");
    }
    // ... or, under that bound, by the memory estimate, with the figure (before the solve).
    let e = run(&config_with(dir.path(), &cfg, "long.toml", "exposure_us", "3e6"), Some("0.1"));
    assert!(e.contains("this reconstruction") && e.contains("frames of 32 x 40") && e.contains("GiB") && e.contains("ROLLCAM_MEMORY_LIMIT_GB"), "{e}");
    assert!(!dir.path().join("never").join("summary.json").exists());
}

#[test]
fn nonsense_values_are_refused_with_the_flag_named() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let out = s(&dir.path().join("never"));
    for (flag, value) in [("--rel-tol", "nan"), ("--rel-tol", "-1"), ("--time-budget-s", "-1"), ("--time-budget-s", "nan"), ("--obj-tol", "inf")] {
        let arg = format!("{flag}={value}");
        let e = fails(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, &arg, "--out", &out], dir.path()));
        assert!(e.contains(flag) || e.contains(&flag[2..].replace('-', "_")), "{arg}: {e}");
        let e = fails(&rollcam(&["compare", "--raw", &raw, "--psf", &psf, "--config", &cfg, &arg, "--out", &out], dir.path()));
        assert!(e.contains(flag), "compare {arg}: {e}");
    }
    let e = fails(&rollcam(&["simulate", "--captures", "100000", "--out", &out], dir.path()));
    assert!(e.contains("--captures") && e.contains("10000"), "{e}");
    let e = fails(&rollcam(&["simulate", "--rows", "200000000", "--out", &out], dir.path()));
    assert!(e.contains("--rows"), "{e}");
    // A flag's value that breaks a valid capture.toml is the flag's error, not the file's.
    let e = fails(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--downsample", "0", "--out", &out], dir.path()));
    assert!(e.contains("--downsample = 0") && !e.contains("capture.toml"), "{e}");
}

#[test]
fn garbage_data_is_refused_not_solved() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let out = s(&dir.path().join("never"));
    // A raw of 3e38: before, tau became 0 and an all-zero video was written.
    let huge = dir.path().join("huge.tiff");
    rollcam::io::write_tiff_f32(&huge, ndarray::Array3::<f32>::from_elem((32, 40, 1), 3e38).view()).unwrap();
    let e = fails(&rollcam(&["reconstruct", "--raw", &s(&huge), "--psf", &psf, "--config", &cfg, "--out", &out], dir.path()));
    assert!(e.contains("huge.tiff") && e.contains("at most 1e18"), "{e}");
    // A truth with NaN: before, "PSNR inf dB".
    let truth = dir.path().join("sim/truth.npy");
    let mut t = rollcam::io::read_npy(&truth).unwrap();
    t[[2, 3, 4, 0]] = f32::NAN;
    let bad = dir.path().join("nan-truth.npy");
    rollcam::io::write_npy(&bad, t.view()).unwrap();
    for cmd in ["reconstruct", "compare"] {
        let e = fails(&rollcam(&[cmd, "--raw", &raw, "--psf", &psf, "--config", &cfg, "--truth", &s(&bad), "--out", &out], dir.path()));
        assert!(e.contains("nan-truth.npy") && e.contains("NaN") && e.contains("frame 2, row 3, col 4"), "{cmd}: {e}");
    }
    assert!(!Path::new(&out).join("summary.json").exists());
}

#[test]
fn a_multi_page_raw_needs_page_and_page_chooses() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    // Two pages: a blank one, then the capture.
    let img = rollcam::io::read_image(&raw).unwrap();
    let mut stack = ndarray::Array4::<f32>::zeros((2, img.dim().0, img.dim().1, 1));
    stack.index_axis_mut(ndarray::Axis(0), 1).assign(&img);
    let two = dir.path().join("two.tiff");
    rollcam::io::write_tiff_stack_f32(&two, stack.view()).unwrap();
    let out = |n: &str| s(&dir.path().join(n));
    let e = fails(&rollcam(&["reconstruct", "--raw", &s(&two), "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &out("r0")], dir.path()));
    assert!(e.contains("two.tiff") && e.contains("holds 2 pages") && e.contains("--page"), "{e}");
    // A multi-page PSF is refused without pointing at `--page` (which picks the raw's page).
    let e = fails(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &s(&two), "--config", &cfg, "--iters", "3", "--out", &out("p0")], dir.path()));
    assert!(e.contains("two.tiff") && e.contains("holds 2 pages") && !e.contains("--page"), "{e}");
    let e =
        fails(&rollcam(&["reconstruct", "--raw", &s(&two), "--page", "3", "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &out("r3")], dir.path()));
    assert!(e.contains("two.tiff") && e.contains('2'), "{e}");
    ok(&rollcam(&["reconstruct", "--raw", &s(&two), "--page", "2", "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &out("r2")], dir.path()));
    ok(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &out("ref")], dir.path()));
    let a = rollcam::io::read_npy(dir.path().join("r2/video.npy")).unwrap();
    let b = rollcam::io::read_npy(dir.path().join("ref/video.npy")).unwrap();
    assert_eq!(a, b, "page 2 is the capture itself");
}

#[test]
fn a_session_that_cannot_fit_its_workers_is_refused_before_recording() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("session");
    let o = rollcam_env(
        &["run", "--camera", "sim", "--sim-scene", "led-array", "--frames", "1", "--workers", "2", "--out", &s(&out)],
        &dir.path().join("cache"),
        &[("ROLLCAM_MEMORY_LIMIT_GB", "0.001")],
    );
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("2 worker(s)") && e.contains("ROLLCAM_MEMORY_LIMIT_GB"), "{e}");
    assert!(!out.join("raw").exists(), "nothing recorded");
}

/// `mpirun -np R rollcam ...` with a build that solves on one machine: every copy
/// refuses before doing anything (instead of R copies writing one folder); one process
/// under a launcher (size 1) runs as usual.
#[test]
fn copies_started_by_an_mpi_launcher_refuse_to_run() {
    let dir = tempfile::tempdir().unwrap();
    for (var, size) in [("OMPI_COMM_WORLD_SIZE", "2"), ("PMI_SIZE", "3")] {
        let out = dir.path().join(format!("demo-{var}"));
        let e = fails(&rollcam_env(&["demo", "--out", out.to_str().unwrap()], dir.path(), &[(var, size)]));
        assert!(e.contains(&format!("one of {size} MPI processes ({var}={size})")) && e.contains("without mpirun"), "{e}");
        assert!(!out.exists(), "{var}: the refused command created {}", out.display());
    }
    let out = dir.path().join("sim");
    ok(&rollcam_env(&["simulate", "--rows", "32", "--cols", "48", "--out", out.to_str().unwrap()], dir.path(), &[("OMPI_COMM_WORLD_SIZE", "1")]));
    assert!(out.join("raw.tiff").is_file());
}

// The second probe (issue 32): inputs that panicked, aborted, hung or gave garbage.

/// Stderr of a run that must be refused with exit 1 (2: by the flag parser): not a
/// panic (101), not an abort or any other signal.
fn refused(o: &std::process::Output) -> String {
    let e = fails(o);
    assert!(matches!(o.status.code(), Some(1 | 2)), "expected a refusal (exit 1 or 2), got {:?}: {e}", o.status);
    assert!(!e.contains("panicked"), "{e}");
    e
}

/// `.npy` bytes of `img` (rows x cols) as float32 in Fortran (column-major) order, as
/// NumPy saves a transposed image.
fn fortran_npy(img: &ndarray::Array2<f32>) -> Vec<u8> {
    let (r, c) = img.dim();
    let mut header = format!("{{'descr': '<f4', 'fortran_order': True, 'shape': ({r}, {c}), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    for j in 0..c {
        for i in 0..r {
            out.extend(img[[i, j]].to_le_bytes());
        }
    }
    out
}

#[test]
fn a_fortran_order_npy_raw_and_psf_are_read_as_the_images_they_hold() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let mut paths = Vec::new();
    for (name, src) in [("raw", &raw), ("psf", &psf)] {
        let img = rollcam::io::read_image(src).unwrap().index_axis(ndarray::Axis(2), 0).to_owned();
        let p = dir.path().join(format!("{name}-f.npy"));
        std::fs::write(&p, fortran_npy(&img)).unwrap();
        let back = rollcam::io::read_image(&p).unwrap();
        assert!(back.is_standard_layout());
        assert_eq!(back.index_axis(ndarray::Axis(2), 0), img, "{name}");
        paths.push(s(&p));
    }
    // Used to panic in model/prepare.rs (a slice of a non-standard layout).
    let out = |n: &str| s(&dir.path().join(n));
    ok(&rollcam(&["reconstruct", "--raw", &paths[0], "--psf", &paths[1], "--config", &cfg, "--iters", "3", "--out", &out("f")], dir.path()));
    ok(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &out("c")], dir.path()));
    let (f, c) = (rollcam::io::read_npy(dir.path().join("f/video.npy")).unwrap(), rollcam::io::read_npy(dir.path().join("c/video.npy")).unwrap());
    let diff = f.iter().zip(&c).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    let peak = c.iter().cloned().fold(0.0f32, f32::max);
    assert!(diff <= 1e-4 * peak, "the Fortran-order inputs give another video: {diff} of {peak}");
}

#[test]
fn numbers_that_panicked_or_aborted_are_refused_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let d = dir.path();
    let never = s(&d.join("never"));
    let rec = s(&d.join("rec"));
    ok(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &rec], d));
    let seq = s(&d.join("seq"));
    ok(&rollcam(&["simulate", "--captures", "3", "--rows", "32", "--cols", "40", "--spacing-px", "6", "--out", &seq], d));
    let solve = ["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &never];
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        // "Lipschitz constant must be positive" (a panic).
        ([&solve[..], &["--binning", "1000000000000000"]].concat(), &["binning", "at most"]),
        // Reported as "inf" (the text read into an f32 first).
        ([&solve[..], &["--tau", "1e308"]].concat(), &["--tau", "1e308: expected a number within", "32-bit"]),
        ([&solve[..], &["--tau-rel=-1e39"]].concat(), &["--tau-rel", "-1e39: expected a number within"]),
        // f64::clamp of NaN (a panic); a contrast of 1.5e16; 6.5 GB of harmonics.
        (vec!["analyze", &rec, "--waveform-period-us", "2640", "--duty", "nan", "--out", &never], &["--duty"]),
        (vec!["analyze", &rec, "--waveform-period-us", "2640", "--duty", "2", "--out", &never], &["--duty", "between 0 and 1"]),
        (vec!["analyze", &rec, "--waveform-period-us", "1e308", "--out", &never], &["--waveform-period-us", "at most 100 times"]),
        (vec!["analyze", &rec, "--waveform-period-us", "1e9", "--out", &never], &["--waveform-period-us"]),
        // time_grid.rs (a panic) and 72 GB (an abort).
        (vec!["reconstruct-sequence", &seq, "--frame-period-us", "1e308", "--iters", "2", "--out", &never], &["frame period", "1000000 video frames"]),
        (vec!["reconstruct-sequence", &seq, "--frame-period-us", "1e12", "--iters", "2", "--out", &never], &["frame period", "1000000 video frames"]),
        // 893 GB, 17.5 GB, a hang, a NaN in capture.toml, a silent 1.
        (vec!["simulate", "--substeps", "4294967295", "--rows", "32", "--cols", "40", "--out", &never], &["--substeps = 4294967295", "1 to 64"]),
        (vec!["simulate", "--lenslets", "1000000000", "--rows", "32", "--cols", "40", "--out", &never], &["--lenslets = 1000000000", "100000"]),
        (vec!["simulate", "--calibration-shots", "1000000", "--rows", "32", "--cols", "40", "--out", &never], &["--calibration-shots = 1000000", "1000"]),
        (vec!["simulate", "--scene", "moving-disc", "--disc-px-per-ms", "nan", "--rows", "32", "--cols", "40", "--out", &never], &["--disc-px-per-ms = NaN"]),
        (vec!["simulate", "--psf", &psf, "--psf-downsample", "0", "--out", &never], &["--psf-downsample = 0"]),
        // Panics of `run` and its acquisition thread (exit 0, "finished").
        (vec!["run", "--camera", "sim", "--frames", "1", "--queue", "18446744073709551615", "--out", &never], &["--queue", "1 to 1024"]),
        (vec!["run", "--camera", "sim", "--frames", "1", "--stall-limit-s", "nan", "--out", &never], &["--stall-limit-s"]),
        (vec!["run", "--camera", "sim", "--frames", "1", "--serve", "127.0.0.1:0", "--serve-linger-s", "1e308", "--out", &never], &["--serve-linger-s"]),
        (vec!["run", "--camera", "sim", "--sim-size", "48x64", "--frames", "1", "--frame-rate-hz", "0", "--out", &never], &["AcquisitionFrameRate"]),
        (vec!["run", "--camera", "sim", "--sim-size", "48x64", "--frames", "1", "--frame-rate-hz", "nan", "--out", &never], &["AcquisitionFrameRate"]),
        (vec!["run", "--camera", "sim", "--sim-size", "100000x100000", "--frames", "1", "--out", &never], &["--sim-size", "65536"]),
        (vec!["run", "--camera", "sim", "--sim-size", "48x64", "--roi", "0,0,32,32", "--frames", "1", "--out", &never], &["--roi", "whole 48 x 64"]),
        // An all-zero video "converged"; inner loops past any time budget.
        (vec!["compare", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--solvers", "admm", "--admm-cg", "0", "--out", &never], &["--admm-cg"]),
        (vec!["compare", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--solvers", "admm", "--admm-mu", "nan", "--out", &never], &["--admm-mu"]),
        (vec!["compare", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--solvers", "admm:cg=18446744073709551615", "--out", &never], &["cg", "1000"]),
        ([&solve[..], &["--tv-prox", "dual4294967296"]].concat(), &["dualN", "1000"]),
        (vec!["bench", "--threads", "100000"], &["--threads"]),
        (vec!["bench", "--psnr", "--target-db", "nan"], &["--target-db"]),
        // "recorded 0 frames", then a reconstruct command for a frame that is not there.
        (vec!["capture", "--camera", "sim:led-array", "--frames", "0", "--out", &never], &["--frames", "0"]),
        // Waited forever.
        (vec!["serve", "/nonexistent-rollcam-session"], &["no such folder"]),
    ];
    for (args, words) in cases {
        let e = refused(&rollcam(&args, d));
        assert!(words.iter().all(|w| e.contains(w)), "{args:?}: {e}");
    }
}

#[test]
fn a_pause_of_minutes_between_captures_is_refused_not_allocated() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let seq = d.join("seq");
    ok(&rollcam(&["simulate", "--captures", "3", "--rows", "32", "--cols", "40", "--spacing-px", "6", "--out", &s(&seq)], d));
    // A 1000 s pause before the last capture: 55 GB asked for (an abort).
    let side = seq.join("frame_000002.json");
    let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&side).unwrap()).unwrap();
    let t = v["device_timestamp_ns"].as_u64().unwrap();
    v["device_timestamp_ns"] = (t + 1_000_000_000_000).into();
    std::fs::write(&side, serde_json::to_string(&v).unwrap()).unwrap();
    let e = refused(&rollcam(&["reconstruct-sequence", &s(&seq), "--iters", "2", "--out", &s(&d.join("never"))], d));
    assert!(e.contains("pause") && e.contains("before capture 2") && e.contains("split the capture folder"), "{e}");
}

#[test]
fn fifos_and_devices_are_refused_as_inputs_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let d = dir.path();
    let fifo = d.join("fifo.tiff");
    assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let fifo = s(&fifo);
    let never = s(&d.join("never"));
    // /dev/zero under an image's name took 22 GB in 20 s.
    let zero = d.join("zero.tiff");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    let zero = s(&zero);
    for (args, word) in [
        (vec!["reconstruct", "--raw", &fifo, "--psf", &psf, "--config", &cfg, "--out", &never], "FIFO"),
        (vec!["reconstruct", "--raw", &zero, "--psf", &psf, "--config", &cfg, "--out", &never], "device"),
        (vec!["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &fifo, "--out", &never], "FIFO"),
        (vec!["calibrate", "--dark", &fifo, "--out", &never], "FIFO"),
    ] {
        let e = refused(&rollcam(&args, d));
        assert!(e.contains(word) && e.contains("regular file"), "{args:?}: {e}");
    }
}

#[test]
fn a_malformed_or_unreadable_lipschitz_cache_entry_is_ignored_aloud() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let cache = dir.path().join("cache");
    let run = |out: &str| {
        let o = rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "5", "--out", out], &cache);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (rollcam::io::read_npy(Path::new(out).join("video.npy")).unwrap(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let (reference, _) = run(&s(&dir.path().join("rec0")));
    let entries: Vec<PathBuf> = std::fs::read_dir(cache.join("lipschitz")).unwrap().map(|e| e.unwrap().path()).collect();
    // `[1,2,3]` read as lambda_max = 1; a link to /dev/zero hung every reconstruct.
    for (i, bad) in ["[1,2,3]", "/dev/zero"].iter().enumerate() {
        for e in &entries {
            std::fs::remove_file(e).unwrap();
            if bad.starts_with('/') {
                std::os::unix::fs::symlink(bad, e).unwrap();
            } else {
                std::fs::write(e, bad).unwrap();
            }
        }
        let (video, stderr) = run(&s(&dir.path().join(format!("rec{}", i + 1))));
        assert_eq!(video, reference, "{bad}");
        assert!(stderr.contains("malformed Lipschitz cache entry"), "{bad}: {stderr}");
    }
}

#[test]
fn bench_markdown_never_edits_a_file_without_its_markers() {
    let dir = tempfile::tempdir().unwrap();
    let notes = dir.path().join("notes.md");
    std::fs::write(&notes, "# my notes\n").unwrap();
    let e = refused(&rollcam(&["bench", "--preset", "small", "--iters", "1", "--warmup", "0", "--reference-reps", "0", "--markdown", &s(&notes)], dir.path()));
    assert!(e.contains("notes.md") && e.contains("markers"), "{e}");
    assert_eq!(std::fs::read_to_string(&notes).unwrap(), "# my notes\n");
}

#[test]
fn a_raw_with_no_light_above_the_dark_is_refused_naming_the_dark_and_the_maximum() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let d = dir.path();
    let never = s(&d.join("never"));
    // Each gave an all-zero video with tau = 0, exit 0.
    // An 8-bit export (values up to 99) of a capture whose dark_level is 100.
    let export = d.join("export.png");
    image::GrayImage::from_fn(40, 32, |x, y| image::Luma([((7 * x + y) % 100) as u8])).save(&export).unwrap();
    let dark_100 = config_with(d, &cfg, "dark100.toml", "dark_level", "100.0");
    // A constant raw (the dark estimated from it is its value).
    let constant = d.join("constant.tiff");
    rollcam::io::write_tiff_f32(&constant, ndarray::Array3::<f32>::from_elem((32, 40, 1), 100.0).view()).unwrap();
    let without_dark = d.join("nodark.toml");
    std::fs::write(&without_dark, std::fs::read_to_string(&cfg).unwrap().lines().filter(|l| !l.starts_with("dark_level =")).collect::<Vec<_>>().join("\n"))
        .unwrap();
    let max_raw = rollcam::io::read_image(Path::new(&raw)).unwrap().fold(0.0f32, |m, &v| m.max(v));
    for (args, dark, max) in [
        (vec!["reconstruct", "--raw", &s(&export), "--psf", &psf, "--config", &dark_100, "--out", &never], "dark_level = 100", "99".to_string()),
        (
            vec!["reconstruct", "--raw", &s(&constant), "--psf", &psf, "--config", &s(&without_dark), "--out", &never],
            "100 counts, estimated",
            "100".to_string(),
        ),
        (
            vec!["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--background", &raw, "--out", &never],
            "the background frame, pixel by pixel",
            format!("{max_raw}"),
        ),
    ] {
        let e = refused(&rollcam(&args, d));
        assert!(e.contains("no pixel is above the dark level") && e.contains(args[2]) && e.contains(dark), "{args:?}: {e}");
        assert!(e.contains(&format!("the raw's largest value is {max} counts")), "{args:?}: {e}");
        assert!(!d.join("never").exists());
    }
}

#[test]
fn a_misspelt_scene_key_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let d = dir.path();
    let never = s(&d.join("never"));
    // `static_backgroud=true` was ignored and not recorded.
    let e = refused(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--scene", "static_backgroud=true", "--out", &never], d));
    assert!(e.contains("static_backgroud") && e.contains("static_background") && e.contains("tv_weights"), "{e}");
    // The simulation's capture.toml ends with its [scene] table.
    let typo = d.join("typo.toml");
    std::fs::write(&typo, std::fs::read_to_string(&cfg).unwrap() + "\nstatic_backgroud = true\n").unwrap();
    let typo = s(&typo);
    let e = refused(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &typo, "--out", &never], d));
    assert!(e.contains("did you mean static_background"), "{e}");
}

#[test]
fn an_all_zero_truth_gives_no_error_figures_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let truth: ndarray::Array4<f32> = rollcam::io::read_npy(dir.path().join("sim/truth.npy")).unwrap();
    let zeros = dir.path().join("zeros.npy");
    rollcam::io::write_npy(&zeros, ndarray::Array4::<f32>::zeros(truth.dim()).view()).unwrap();
    let out = dir.path().join("rec");
    let o = rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "5", "--truth", &s(&zeros), "--out", &s(&out)], dir.path());
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stderr}");
    // Used to print "PSNR -inf dB".
    assert!(!stdout.contains("inf") && !stdout.contains("NaN"), "{stdout}");
    assert!(stdout.contains("the truth is zero everywhere") && stdout.contains("undefined"), "{stdout}");
    let text = std::fs::read_to_string(out.join("summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&text).unwrap();
    for key in ["psnr_db", "rel_error", "rel_error_scaled"] {
        assert!(summary[key].is_null(), "{key}: {text}");
    }
    assert!(summary["error_undefined"].as_str().unwrap().contains("zero everywhere"), "{text}");
    let trace = std::fs::read_to_string(out.join("trace.csv")).unwrap();
    assert!(!trace.contains("inf") && !trace.contains("NaN"), "{trace}");
}

#[test]
fn compare_refuses_an_input_named_like_a_runs_video_before_any_solve() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    // The truth is a video of an earlier compare's folder, and that folder is the output.
    let out = dir.path().join("cmp");
    std::fs::create_dir_all(out.join("videos")).unwrap();
    let truth = out.join("videos/fista.npy");
    std::fs::copy(dir.path().join("sim/truth.npy"), &truth).unwrap();
    let before = std::fs::read(&truth).unwrap();
    let o = rollcam(
        &["compare", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--truth", &s(&truth), "--solvers", "fista", "--iters", "5", "--out", &s(&out), "--force"],
        dir.path(),
    );
    let e = fails(&o);
    assert!(e.contains("videos/fista.npy") && e.contains("--truth") && e.contains("never overwritten"), "{e}");
    // Refused before the problem was built or any solver ran.
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(!stdout.contains("problem:"), "{stdout}");
    assert_eq!(std::fs::read(&truth).unwrap(), before);
}

/// The fourth probe: `capture --force` wrote through a link planted under the temporary
/// name of capture.json or a frame's files, replacing the file outside the folder and
/// leaving the frame a link to it. The temporary files are created anew under fresh
/// names: the outside file keeps its bytes, every recorded file is a regular file, and
/// the planted links are left as they were (not this command's to remove).
#[test]
fn capture_force_never_writes_through_a_planted_temporary_link() {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    std::fs::create_dir(&cap).unwrap();
    let outside = dir.path().join("precious.txt");
    std::fs::write(&outside, b"precious").unwrap();
    let planted = [".capture.json.tmp", ".frame_000000.tiff.tmp", ".frame_000000.json.tmp"];
    for name in planted {
        std::os::unix::fs::symlink(&outside, cap.join(name)).unwrap();
    }
    ok(&rollcam(&["capture", "--camera", "sim:led-array", "--frames", "1", "--out", &s(&cap), "--force"], dir.path()));
    assert_eq!(std::fs::read(&outside).unwrap(), b"precious");
    for name in ["capture.json", "frame_000000.tiff", "frame_000000.json"] {
        let m = std::fs::symlink_metadata(cap.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(m.file_type().is_file(), "{name} is not a regular file");
    }
    for name in planted {
        assert!(std::fs::symlink_metadata(cap.join(name)).unwrap().file_type().is_symlink(), "{name} was removed");
    }
}

/// The third probe's aborts and panics of `simulate`: a grid, an exposure and a frame
/// period outside what memory and the time grid allow, each refused naming its flag
/// before anything of that size is allocated.
#[test]
fn simulate_sizes_outside_the_budget_and_time_grid_are_refused_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let never = s(&d.join("never"));
    let small = ["--rows", "32", "--cols", "40", "--spacing-px", "6"];
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        // An abort allocating 34 GB for the synthetic PSF.
        (vec!["simulate", "--rows", "65536", "--cols", "65536", "--out", &never], &["simulating 1 capture(s) of 65536 x 65536", "of memory"]),
        // An abort allocating 145 GB of integration steps.
        (
            [&["simulate", "--shutter", "global", "--exposure-us", "1e12", "--out", &never][..], &small[..]].concat(),
            &["--exposure-us = 1000000000000", "sub-steps"],
        ),
        // A panic (ndarray shape overflow).
        (
            [&["simulate", "--captures", "2", "--frame-period-us", "18446744073709551616", "--out", &never][..], &small[..]].concat(),
            &["--frame-period-us", "1000000 video frames"],
        ),
        // Exit 0 with capture 1's device timestamp pinned at u64::MAX.
        (
            [&["simulate", "--captures", "2", "--frame-period-us", "1e308", "--out", &never][..], &small[..]].concat(),
            &["--frame-period-us", "1000000 video frames"],
        ),
    ];
    for (args, words) in cases {
        let e = refused(&rollcam(&args, d));
        assert!(words.iter().all(|w| e.contains(w)), "{args:?}: {e}");
        assert!(!Path::new(&never).exists(), "{args:?}");
    }
}

/// Every use of the fake camera wrote `$TMPDIR/rollcam-fake-camera-<pid>.xml` with a
/// plain write (a planted link followed) and never removed it: now a private folder,
/// gone when the command ends.
#[cfg(feature = "aravis")]
#[test]
fn the_fake_cameras_xml_leaves_nothing_in_the_temporary_directory() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let out = ok(&rollcam_env(&["devices", "--fake"], dir.path(), &[("TMPDIR", tmp.to_str().unwrap())]));
    assert!(out.contains("Fake_1"), "{out}");
    let left: Vec<_> = std::fs::read_dir(&tmp).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    // A refused capture (an error path) leaves nothing either.
    let e = fails(&rollcam_env(
        &["capture", "--camera", "aravis:Fake_1", "--frames", "0", "--out", &s(&dir.path().join("never"))],
        dir.path(),
        &[("TMPDIR", tmp.to_str().unwrap())],
    ));
    assert!(e.contains("--frames"), "{e}");
    assert_eq!(std::fs::read_dir(&tmp).unwrap().count(), 0);
}

/// The third probe's silent garbage and unclear refusals: values without a physical
/// range, flags meaningless alone, and messages that contradicted themselves. Each is
/// refused naming the flag or file and what was expected.
#[test]
fn third_probe_values_without_a_physical_range_are_refused_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let d = dir.path();
    let never = s(&d.join("never"));
    let rec = s(&d.join("rec"));
    ok(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &rec], d));
    let seq = s(&d.join("seq"));
    ok(&rollcam(&["simulate", "--captures", "2", "--rows", "32", "--cols", "40", "--spacing-px", "6", "--out", &seq], d));
    // A flat PSF (every pixel 65535) and a background frame with a negative value.
    let flat = s(&d.join("flat.tiff"));
    rollcam::io::write_tiff_u16(&flat, ndarray::Array3::<f32>::from_elem((32, 40, 1), 65535.0).view()).unwrap();
    let mut bg = ndarray::Array3::<f32>::from_elem((32, 40, 1), 100.0);
    bg[[3, 5, 0]] = -7.5;
    let negative = s(&d.join("negative.tiff"));
    rollcam::io::write_tiff_f32(&negative, bg.view()).unwrap();
    let a_file = s(&d.join("a_file"));
    std::fs::write(&a_file, b"not a folder").unwrap();
    let solve = ["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &never];
    let compare = ["compare", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &never];
    let sequence = ["reconstruct-sequence", &seq, "--iters", "2", "--out", &never];
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        // "converged after 5 iterations" at tolerances no relative change reaches.
        ([&solve[..], &["--obj-tol", "1e308"]].concat(), &["--obj-tol", "below 1"]),
        ([&solve[..], &["--rel-tol", "1e39"]].concat(), &["rel", "below 1"]),
        ([&compare[..], &["--rel-tol", "1.8e19"]].concat(), &["rel", "below 1"]),
        ([&sequence[..], &["--obj-tol", "1e308"]].concat(), &["obj", "below 1"]),
        // A flat PSF: "0 clipped pixels" (calibrate refuses the same data).
        (vec!["reconstruct", "--raw", &raw, "--psf", &flat, "--config", &cfg, "--out", &never], &["flat.tiff", "65535 counts at every pixel"]),
        // A negative float background: accepted.
        ([&solve[..], &["--background", &negative]].concat(), &["negative.tiff", "non-negative", "-7.5 at row 3, col 5"]),
        // Every raw pixel at 65535, exit 0.
        (vec!["simulate", "--dark-level-adu", "1e308", "--rows", "32", "--cols", "40", "--out", &never], &["--dark-level-adu", "full scale", "65535"]),
        (vec!["simulate", "--dark-level-adu", "65535", "--rows", "32", "--cols", "40", "--out", &never], &["--dark-level-adu", "full scale"]),
        // "square wave 0 us (inf Hz)"; "no bright spot above the background".
        (vec!["analyze", &rec, "--waveform-period-us", "1e-320", "--out", &never], &["--waveform-period-us", "a hundredth of a frame"]),
        (vec!["analyze", &rec, "--max-spots", "0", "--out", &never], &["--max-spots", "at least 1"]),
        // The second line, or the second flag, silently dropped.
        ([&solve[..], &["--scene", "static=true\nstatic=false"]].concat(), &["--scene", "one KEY=VALUE"]),
        ([&solve[..], &["--scene", "static=true", "--scene", "static=false"]].concat(), &["--scene", "static is declared twice"]),
        // Stored as null in capture.json.
        (vec!["capture", "--camera", "sim:led-array", "--frames", "1", "--led-phase-us", "nan", "--out", &never], &["--led-phase-us", "finite"]),
        (vec!["capture", "--camera", "sim:led-array", "--frames", "1", "--exposure-us", "inf", "--out", &never], &["--exposure-us", "finite"]),
        // Ignored.
        (vec!["run", "--camera", "sim", "--frames", "1", "--retry-failed", "--out", &never], &["--retry-failed", "--resume"]),
        (vec!["run", "--camera", "sim", "--frames", "1", "--truth-dir", &a_file, "--out", &never], &["--truth-dir", "a_file", "found a file"]),
        // Ran to the 4,000-iteration cap.
        (vec!["bench", "--psnr", "--target-db", "1e308"], &["--target-db", "float32"]),
        // Retried, then "is it powered?".
        (vec!["led", "--timeout-ms", "0", "identify"], &["--timeout-ms", "1..=60000"]),
    ];
    for (args, words) in cases {
        let e = refused(&rollcam(&args, d));
        assert!(words.iter().all(|w| e.contains(w)), "{args:?}: {e}");
        assert!(!Path::new(&never).exists(), "{args:?}");
    }
}

/// A raw dark but for one hot pixel: "no pixel is above the dark level ... the raw's
/// largest value is 65535 counts" contradicted itself.
#[test]
fn a_dark_raw_with_one_hot_pixel_says_the_pixel_is_defective() {
    let dir = tempfile::tempdir().unwrap();
    let (_, psf, cfg) = simulated(dir.path());
    let d = dir.path();
    let dark_100 = config_with(d, &cfg, "dark100.toml", "dark_level", "100.0");
    let mut img = ndarray::Array3::<f32>::from_elem((32, 40, 1), 100.0);
    img[[10, 12, 0]] = 65535.0;
    let hot = d.join("hot.tiff");
    rollcam::io::write_tiff_u16(&hot, img.view()).unwrap();
    let e = refused(&rollcam(&["reconstruct", "--raw", &s(&hot), "--psf", &psf, "--config", &dark_100, "--out", &s(&d.join("never"))], d));
    assert!(e.contains("no pixel is above the dark level") && e.contains("the raw's largest value is 100 counts"), "{e}");
    assert!(e.contains("defective") && e.contains("65535"), "{e}");
}

/// The third probe's remainders: an L1 weight that zeroes the video, a solve of years,
/// a recording the disk cannot hold or of hours, and a capture description of another
/// grid than the video's. Each is refused before any work, naming the flag or file and
/// the scale it is judged against; nothing is written.
#[test]
fn work_that_cannot_give_a_result_or_would_not_end_is_refused_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let d = dir.path();
    let never = s(&d.join("never"));
    let seq = s(&d.join("seq"));
    ok(&rollcam(&["simulate", "--captures", "2", "--rows", "32", "--cols", "40", "--spacing-px", "6", "--out", &seq], d));
    let rec = s(&d.join("rec"));
    ok(&rollcam(&["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &rec], d));
    // The video is 32 x 40; a description of 31 rows (and one of 32 x 41) is another capture's.
    let text = std::fs::read_to_string(&cfg).unwrap();
    let other = |name: &str, from: &str, to: &str| {
        let p = d.join(name);
        assert!(text.contains(from), "{text}");
        std::fs::write(&p, text.replace(from, to)).unwrap();
        s(&p)
    };
    let rows_31 = other("rows31.toml", "rows = 32", "rows = 31");
    let cols_41 = other("cols41.toml", "cols = 40", "cols = 41");
    let solve = ["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "3", "--out", &never];
    let sequence = ["reconstruct-sequence", &seq, "--iters", "2", "--out", &never];
    let years = ["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "100000000000000", "--obj-tol", "0", "--out", &never];
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        // An all-zero video, "converged".
        ([&solve[..], &["--l1", "18446744073709551616"]].concat(), &["--l1", "max(A^T b)", "all-zero video is the exact minimiser", "expected l1 below"]),
        ([&solve[..], &["--l1", "1.8e19"]].concat(), &["--l1", "1.8e19", "max(A^T b)"]),
        ([&sequence[..], &["--l1", "1.8e19"]].concat(), &["--l1", "max(A^T b)", "all-zero video"]),
        // compare has no L1 term to give.
        (vec!["compare", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--l1", "1.8e19", "--out", &never], &["--l1"]),
        // "estimated solve time: about 11564455254.0 s", and it started.
        (years.to_vec(), &["years", "beyond a day", "--yes"]),
        // Hours of recording: refused unless confirmed; more than any disk holds: refused.
        (vec!["capture", "--camera", "sim:led-array", "--frames", "400", "--frame-rate-hz", "0.1", "--out", &never], &["--frames = 400", "66.7 min", "--yes"]),
        (
            vec!["capture", "--camera", "sim:led-array", "--frames", "18446744073709551615", "--yes", "--out", &never],
            &["never: the file system has", "free", "TB", "--frames"],
        ),
        // Used without a word.
        (vec!["analyze", &rec, "--config", &rows_31, "--out", &never], &["rows31.toml", "31 x 40", "has frames of 32 x 40"]),
        (vec!["analyze", &rec, "--config", &cols_41, "--out", &never], &["cols41.toml", "32 x 41", "has frames of 32 x 40"]),
    ];
    for (args, words) in cases {
        let e = refused(&rollcam(&args, d));
        assert!(words.iter().all(|w| e.contains(w)), "{args:?}: {e}");
        assert!(!Path::new(&never).exists(), "{args:?}");
    }
    // The estimate comes in human units; a weight below the scale still solves; the
    // video's own description (or the full field of view's grid) is accepted.
    let out = ok(&rollcam(&[&solve[..], &["--l1", "1"]].concat(), d));
    assert!(out.contains("estimated solve time: about ") && out.contains(" s ("), "{out}");
    std::fs::remove_dir_all(&never).unwrap();
    ok(&rollcam(&["analyze", &rec, "--config", &cfg, "--out", &never], d));
}

/// `--yes` starts a solve estimated beyond a day (here stopped by Ctrl-C, which keeps
/// the last iterate and writes the folder, exiting 1: not converged).
#[test]
fn yes_starts_a_solve_estimated_beyond_a_day() {
    use std::io::{BufRead, BufReader};
    let dir = tempfile::tempdir().unwrap();
    let (raw, psf, cfg) = simulated(dir.path());
    let out = dir.path().join("rec");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_rollcam"))
        .args(["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "100000000000000", "--obj-tol", "0", "--yes", "--out", &s(&out)])
        .env("ROLLCAM_CACHE_DIR", dir.path())
        .env("RUST_LOG", "warn")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let estimate = lines.by_ref().map(|l| l.unwrap()).find(|l| l.starts_with("estimated solve time")).expect("an estimate");
    assert!(estimate.contains("years"), "{estimate}");
    std::thread::sleep(std::time::Duration::from_secs(2));
    assert!(std::process::Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap().success());
    let rest: Vec<String> = lines.map(|l| l.unwrap()).collect();
    child.wait().unwrap();
    assert!(rest.iter().any(|l| l.contains("stopped on request")), "{rest:?}");
    assert!(out.join("summary.json").is_file(), "{rest:?}");
}

/// Each use of the fake camera said "configured" twice (the camera configured twice);
/// a recording beyond the disk is refused with its estimate, before the first frame;
/// the log lines on a pipe are plain (no timestamp, no colour codes).
#[cfg(feature = "aravis")]
#[test]
fn the_fake_camera_is_configured_once_and_its_recording_estimated_first() {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    let o = rollcam_env(&["capture", "--camera", "aravis:Fake_1", "--frames", "2", "--out", &s(&cap)], dir.path(), &[("RUST_LOG", "info")]);
    let out = ok(&o);
    assert!(out.contains("recording 2 frames: about 0.1 s and 1.1 MB on disk"), "{out}");
    let log = String::from_utf8_lossy(&o.stderr);
    assert_eq!(log.matches("configured").count(), 1, "{log}");
    assert!(!log.contains('\u{1b}'), "colour codes on a pipe: {log}");
    for line in log.lines().filter(|l| l.contains("INFO")) {
        assert!(line.trim_start().starts_with("INFO"), "a timestamp before the level: {line}");
    }
    let never = s(&dir.path().join("never"));
    let e = refused(&rollcam(&["capture", "--camera", "aravis:Fake_1", "--frames", "18446744073709551615", "--yes", "--out", &never], dir.path()));
    assert!(e.contains("free") && e.contains("528384 bytes per frame"), "{e}");
    assert!(!Path::new(&never).exists());
}
