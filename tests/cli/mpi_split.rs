//! One capture split across MPI ranks by real `mpirun` runs (cargo feature `mpi`; the
//! Debian packages libopenmpi-dev, openmpi-bin and libclang-dev): with 1, 2 and 3
//! ranks the video equals the single process's within 1e-5 relative after a fixed
//! number of iterations, for the dual and the single rolling shutter, with and without
//! a scene declaration, both TV maps, FISTA, MFISTA and PGD, with and without L1; what
//! cannot be split is refused on every rank; summary.json and `bench` report each
//! rank's frames, memory and traffic; the split runs the plan one process runs (the
//! whole grid chosen by the still check) or refuses its mode by name.
#![cfg(feature = "mpi")]

use ndarray::ArrayD;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_rollcam");
const ITERS: &str = "30";

fn rollcam(args: &[&str], cache: &Path) -> Command {
    let mut c = Command::new(BIN);
    c.args(args).env("ROLLCAM_CACHE_DIR", cache).env("RUST_LOG", "warn");
    c
}

/// `mpirun -np ranks rollcam args...` on one machine (oversubscribed: the ranks may
/// outnumber the cores), one thread per rank.
fn mpirun(ranks: usize, args: &[&str], cache: &Path) -> Output {
    let mut c = Command::new("mpirun");
    c.args(["--oversubscribe", "-np", &ranks.to_string(), "-x", "ROLLCAM_CACHE_DIR", "-x", "RAYON_NUM_THREADS", "-x", "RUST_LOG", BIN]).args(args);
    c.env("ROLLCAM_CACHE_DIR", cache).env("RAYON_NUM_THREADS", "1").env("RUST_LOG", "warn");
    c.env("OMPI_ALLOW_RUN_AS_ROOT", "1").env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1").env("OMPI_MCA_rmaps_base_oversubscribe", "1");
    c.output().expect("mpirun runs (apt-get install openmpi-bin)")
}

fn ok(o: Output, what: &str) -> String {
    let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{what} failed:\n{text}");
    text
}

fn video(dir: &Path) -> ArrayD<f32> {
    ndarray_npy::read_npy(dir.join("video.npy")).unwrap()
}

fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

fn rel_diff(a: &ArrayD<f32>, b: &ArrayD<f32>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    let d: f64 = a.iter().zip(b).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum();
    let n: f64 = a.iter().map(|&x| (x as f64).powi(2)).sum();
    (d / n).sqrt()
}

/// A simulated LED capture (64 x 80) with `shutter`.
fn simulate(dir: &Path, shutter: &str) -> PathBuf {
    simulate_with(dir, shutter, &["--shutter", shutter])
}

/// A simulated LED capture (64 x 80) with the flags `extra`, in `dir/sim-label`.
fn simulate_with(dir: &Path, label: &str, extra: &[&str]) -> PathBuf {
    let sim = dir.join(format!("sim-{label}"));
    let mut args = vec!["simulate", "--rows", "64", "--cols", "80", "--seed", "3", "--out", sim.to_str().unwrap()];
    args.extend_from_slice(extra);
    ok(rollcam(&args, &dir.join("cache")).output().unwrap(), "simulate");
    sim
}

/// Run `reconstruct` once alone and with 1, 2 and 3 ranks; every split video equals
/// the single process's within 1e-5 relative. Returns the folders (alone, then by
/// ranks).
fn split_equals_single(dir: &Path, sim: &Path, label: &str, extra: &[&str]) -> Vec<PathBuf> {
    let (raw, psf, cfg, truth) = (sim.join("raw.tiff"), sim.join("psf.tiff"), sim.join("capture.toml"), sim.join("truth.npy"));
    let files = |out: &Path| -> Vec<String> {
        let mut v: Vec<String> = vec!["reconstruct".into(), "--iters".into(), ITERS.into(), "--out".into(), out.display().to_string()];
        for (flag, p) in [("--raw", &raw), ("--psf", &psf), ("--config", &cfg), ("--truth", &truth)] {
            v.extend([flag.to_string(), p.display().to_string()]);
        }
        v.extend(extra.iter().map(|s| s.to_string()));
        // The split solves the whole grid: the single process too (a sparse scene's
        // support is one process's), unless a declaration sets the grid.
        let declares = extra.iter().any(|a| ["--frames", "--support", "--tv-weights", "--static", "--scene", "--scene-colour"].contains(a));
        if !declares {
            v.push("--full-grid".into());
        }
        v
    };
    // The single process and the split runs share one Lipschitz cache only from 2 ranks
    // on: with 1 rank the constant is measured by the split power iteration.
    let cache = dir.join(format!("cache-{label}"));
    let alone = dir.join(format!("{label}-alone"));
    let args = files(&alone);
    ok(rollcam(&args.iter().map(|s| s.as_str()).collect::<Vec<_>>(), &cache).output().unwrap(), "reconstruct alone");
    let v0 = video(&alone);
    let mut outs = vec![alone];
    for ranks in 1..=3 {
        let out = dir.join(format!("{label}-ranks{ranks}"));
        let args = files(&out);
        let own_cache = dir.join(format!("cache-{label}-{ranks}"));
        let cache = if ranks == 1 { &own_cache } else { &cache };
        let text = ok(mpirun(ranks, &args.iter().map(|s| s.as_str()).collect::<Vec<_>>(), cache), &format!("{label}: mpirun -np {ranks}"));
        assert!(text.contains(&format!("split across {ranks} MPI ranks")), "{text}");
        let d = rel_diff(&v0, &video(&out));
        assert!(d <= 1e-5, "{label}, {ranks} ranks: relative difference {d:.3e} from the single process");
        let s = summary(&out);
        // The error against the truth, from sums over the ranks (and, for a frame
        // window, rank 0's frames outside it), is the single process's.
        let s0 = summary(&outs[0]);
        for key in ["psnr_db", "rel_error"] {
            let (a, b) = (s0[key].as_f64().unwrap(), s[key].as_f64().unwrap());
            assert!((a - b).abs() <= 1e-5 * a.abs(), "{label}, {ranks} ranks: {key} {b} against {a}");
        }
        let mpi = &s["mpi"];
        assert_eq!(mpi["ranks"], ranks);
        let per = mpi["per_rank"].as_array().unwrap();
        assert_eq!(per.len(), ranks);
        // Only the rows two blocks' frames touch are summed by the forward.
        let (summed, rows) = (mpi["sensor_rows_summed"].as_u64().unwrap(), mpi["sensor_rows"].as_u64().unwrap());
        assert_eq!(rows, 64);
        assert!(if ranks == 1 { summed == 0 } else { summed > 0 && summed <= 8 * (ranks as u64 - 1) }, "{label}, {ranks} ranks: {summed} rows summed");
        let lipschitz_cached = s["channels"][0]["lipschitz_cached"].as_bool().unwrap();
        // The single process's stored constant serves the ranks (its own key for a
        // declaration too); with 1 rank, in a cache of its own, the ranks measure it.
        assert_eq!(lipschitz_cached, ranks > 1, "{label}, {ranks} ranks");
        for (r, p) in per.iter().enumerate() {
            assert_eq!(p["rank"], r);
            assert!(p["peak_memory_bytes"].as_u64().unwrap() > 0);
            let sent = p["sent_bytes_per_iteration"].as_f64().unwrap();
            if ranks > 1 {
                // At least one edge frame of the unknowns goes out each iteration.
                let shape = if s["scene"].is_null() { &s["video_shape"] } else { &s["scene"]["plan"]["solved_shape"] };
                let frame_bytes = (shape[1].as_u64().unwrap() * shape[2].as_u64().unwrap() * 4) as f64;
                assert!(sent >= frame_bytes, "{label}, rank {r}: {sent} bytes per iteration, frames of {frame_bytes}");
            } else {
                assert_eq!(sent, 0.0);
            }
        }
        outs.push(out);
    }
    outs
}

#[test]
fn a_split_dual_shutter_capture_equals_the_single_process() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path(), "dual");
    let outs = split_equals_single(dir.path(), &sim, "dual", &[]);
    // The other gradient solvers, and an L1 term beside TV.
    split_equals_single(dir.path(), &sim, "pgd", &["--solver", "pgd"]);
    split_equals_single(dir.path(), &sim, "mfista-l1", &["--solver", "mfista", "--l1", "0.3"]);
    // The blocks cover the frames in order; the summary's error is the single process's.
    let s0 = summary(&outs[0]);
    let frames = s0["video_shape"][0].as_u64().unwrap();
    for out in &outs[1..] {
        let s = summary(out);
        let per = s["mpi"]["per_rank"].as_array().unwrap();
        assert_eq!(per[0]["frames"][0], 0);
        assert_eq!(per[per.len() - 1]["frames"][1], frames);
        for w in per.windows(2) {
            assert_eq!(w[0]["frames"][1], w[1]["frames"][0]);
        }
        let share: f64 = per.iter().map(|p| p["work_share"].as_f64().unwrap()).sum();
        assert!((share - 1.0).abs() < 1e-9);
        let (e0, e) = (s0["rel_error"].as_f64().unwrap(), s["rel_error"].as_f64().unwrap());
        assert!((e0 - e).abs() <= 1e-5 * e0, "{e0} vs {e}");
        let (o0, o) = (s0["channels"][0]["objective"].as_f64().unwrap(), s["channels"][0]["objective"].as_f64().unwrap());
        assert!((o0 - o).abs() <= 1e-5 * o0, "{o0} vs {o}");
        // The trace has every iteration.
        let trace = std::fs::read_to_string(out.join("trace.csv")).unwrap();
        assert_eq!(trace.lines().count(), 1 + ITERS.parse::<usize>().unwrap());
    }
}

#[test]
fn a_split_single_shutter_capture_with_a_scene_declaration_equals_the_single_process() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path(), "rolling");
    split_equals_single(dir.path(), &sim, "rolling", &[]);
    // A frame window, a support box and TV weights: declared unknowns split.
    let outs = split_equals_single(dir.path(), &sim, "declared", &["--frames", "4..40", "--support", "8,56,10,70", "--tv-weights", "3,1,1"]);
    // The exact (dual) TV map, its inner iterations exchanging edge frames.
    let dual = split_equals_single(dir.path(), &sim, "dual-map", &["--tv-prox", "dual10"]);
    for out in &dual {
        assert_eq!(summary(out)["channels"][0]["tv_prox"], "dual10", "{}", out.display());
    }
    for out in &outs {
        let s = summary(out);
        assert_eq!(s["scene"]["plan"]["frames"], serde_json::json!([4, 40]), "{}", out.display());
    }
}

#[test]
fn a_split_capture_with_sensor_defects_and_clipped_pixels_equals_the_single_process() {
    // Hot and stuck pixels (left out of the data term) and clipped ones (one-sided):
    // the masked operator and the one-sided data term, each sensor row counted once.
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate_with(dir.path(), "defects", &["--sensor-defects", "--bit-depth", "12", "--e-per-us", "4000"]);
    let outs = split_equals_single(dir.path(), &sim, "defects", &[]);
    let sensor = &summary(&outs[2])["sensor"];
    assert!(sensor["lower_bound_pixels"].as_u64().unwrap() > 0 && sensor["masked_pixels"].as_u64().unwrap() > 0, "{sensor}");
}

/// `reconstruct` of `sim` with `extra`, alone (`ranks` 0) or under `mpirun -np ranks`,
/// into `out`: the exit status and everything printed.
fn reconstruct_as(sim: &Path, out: &Path, ranks: usize, extra: &[&str], cache: &Path) -> (bool, String) {
    let s = |f: &str| sim.join(f).display().to_string();
    let (raw, psf, cfg) = (s("raw.tiff"), s("psf.tiff"), s("capture.toml"));
    let mut args = vec!["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", ITERS, "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let o = if ranks == 0 { rollcam(&args, cache).output().unwrap() } else { mpirun(ranks, &args, cache) };
    (o.status.success(), format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr)))
}

#[test]
fn the_split_solves_the_plan_one_process_solves_or_refuses_it_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    // A moving disc: one process plans the plain video on the whole grid from its still
    // check (nothing declared, no --full-grid); the split runs the same plan.
    let disc = simulate_with(dir.path(), "disc", &["--scene", "moving-disc"]);
    let alone = dir.path().join("disc-alone");
    let (done, text) = reconstruct_as(&disc, &alone, 0, &[], &cache);
    assert!(done, "{text}");
    assert!(text.contains("plan: the plain video on the whole grid (one process)"), "{text}");
    let split = dir.path().join("disc-split");
    let (done, text) = reconstruct_as(&disc, &split, 2, &[], &cache);
    assert!(done, "{text}");
    assert!(text.contains("plan: the plain video on the whole grid (split across 2 MPI ranks)"), "{text}");
    let d = rel_diff(&video(&alone), &video(&split));
    assert!(d <= 1e-4, "the split's video differs from one process's by {d:.3e}");
    let (p0, p2) = (summary(&alone)["plan"].clone(), summary(&split)["plan"].clone());
    assert_eq!(p0["mode"], "whole-grid");
    assert_eq!(p2["mode"], "whole-grid");
    assert_eq!(p0["tau"], p2["tau"]);
    assert_eq!(p2["processes"], serde_json::json!({"kind": "split", "ranks": 2}));
    // --explain under mpirun: the plan on rank 0, nothing solved or written.
    let explained = dir.path().join("disc-explained");
    let (done, text) = reconstruct_as(&disc, &explained, 2, &["--explain"], &cache);
    assert!(done && text.contains("plan: the plain video on the whole grid") && text.contains("--explain"), "{text}");
    assert!(!explained.exists(), "--explain created {}", explained.display());

    // Flashing LEDs: one process solves the sparse scene's support and sources; the
    // split refuses by name and says how to get the whole grid, before any solve.
    let leds = simulate(dir.path(), "dual");
    let out = dir.path().join("leds-split");
    let (done, text) = reconstruct_as(&leds, &out, 2, &[], &cache);
    assert!(!done, "{text}");
    assert!(text.contains("one process solves this capture as a sparse scene") && text.contains("give --full-grid"), "{text}");
    assert!(!out.join("video.npy").exists());
    let (_, text) = reconstruct_as(&leds, &dir.path().join("leds-explained"), 0, &["--explain"], &cache);
    assert!(text.contains("plan: a sparse scene"), "{text}");

    // A disc over texture: one process chooses the static + dynamic model; the split
    // refuses by name, naming the flag that solves the plain video.
    let dense = simulate_with(dir.path(), "dense", &["--scene", "disc-over-texture"]);
    let out = dir.path().join("dense-split");
    let (done, text) = reconstruct_as(&dense, &out, 2, &[], &cache);
    assert!(!done, "{text}");
    assert!(text.contains("with the static + dynamic model") && text.contains("--scene static_background=false"), "{text}");
    assert!(!out.join("video.npy").exists());
    // With that flag both solve the plain video, alike.
    let plain = ["--scene", "static_background=false"];
    let (a, b) = (dir.path().join("dense-plain-alone"), dir.path().join("dense-plain-split"));
    let (done, text) = reconstruct_as(&dense, &a, 0, &plain, &cache);
    assert!(done, "{text}");
    let (done, text) = reconstruct_as(&dense, &b, 2, &plain, &cache);
    assert!(done, "{text}");
    let d = rel_diff(&video(&a), &video(&b));
    assert!(d <= 1e-4, "static_background=false: the split's video differs from one process's by {d:.3e}");
}

#[test]
fn what_cannot_be_split_is_refused_on_every_rank() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path(), "dual");
    let s = |f: &str| sim.join(f).display().to_string();
    let (raw, psf, cfg) = (s("raw.tiff"), s("psf.tiff"), s("capture.toml"));
    for (extra, says) in [
        (vec!["--solver", "admm"], "the admm solver is not split"),
        (vec!["--static"], "a static scene"),
        (vec!["--scene", "static_background=true"], "the static + dynamic model"),
    ] {
        let out = dir.path().join(format!("refused-{}", extra.join("")));
        let mut args = vec!["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "5", "--out", out.to_str().unwrap()];
        args.extend(extra.iter().copied());
        let o = mpirun(2, &args, &dir.path().join("cache"));
        let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
        assert!(!o.status.success(), "{extra:?}: {text}");
        assert!(text.contains(says) && text.contains("run it without mpirun"), "{extra:?}: {text}");
        assert!(!out.join("video.npy").exists());
    }
    // Key frames: refused, not left out unseen.
    let keyed = simulate_with(dir.path(), "keys", &["--keyframes", "first,last"]);
    let k = |f: &str| keyed.join(f).display().to_string();
    let out = dir.path().join("refused-keys");
    let o = mpirun(
        2,
        &["reconstruct", "--raw", &k("raw.tiff"), "--psf", &k("psf.tiff"), "--config", &k("capture.toml"), "--out", out.to_str().unwrap()],
        &dir.path().join("cache"),
    );
    let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(!o.status.success() && text.contains("[[keyframes]]") && text.contains("run it without mpirun"), "{text}");
    assert!(!out.join("video.npy").exists());
    // A truth of another capture's shape: refused (each rank says so, as far as the
    // abort of the first to fail lets it).
    let small = simulate_with(dir.path(), "short", &["--exposure-us", "440"]);
    let out = dir.path().join("refused-truth");
    let truth = small.join("truth.npy");
    let o = mpirun(
        2,
        &["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--truth", truth.to_str().unwrap(), "--out", out.to_str().unwrap()],
        &dir.path().join("cache"),
    );
    let text = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && text.contains("does not match the video's"), "{text}");
    // Other commands do not run as copies.
    let o = mpirun(2, &["simulate", "--rows", "32", "--cols", "48", "--out", dir.path().join("copies").to_str().unwrap()], &dir.path().join("cache"));
    let text = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && text.contains("only `reconstruct` and `bench --preset` split"), "{text}");
}

#[test]
fn bench_under_mpirun_reports_each_ranks_memory_and_traffic() {
    let dir = tempfile::tempdir().unwrap();
    let o = mpirun(2, &["bench", "--preset", "small", "--warmup", "1", "--iters", "3"], &dir.path().join("cache"));
    let text = ok(o, "bench under mpirun");
    let line = text.lines().find(|l| l.starts_with('{')).expect("a JSON line");
    let r: serde_json::Value = serde_json::from_str(line).unwrap();
    assert_eq!(r["ranks"], 2);
    assert_eq!(r["frames"], 34);
    let per = r["per_rank"].as_array().unwrap();
    assert_eq!(per.len(), 2);
    let frame_bytes = (64 * 80 * 4) as f64;
    // Each iteration: the edge frames of the TV map's argument both ways, the new
    // iterate's first frame of rank 1 down (its TV value), and the few sensor rows both
    // blocks' frames touch up to rank 0 and back.
    for (p, frames) in per.iter().zip([1.0, 2.0]) {
        assert!(p["peak_memory_bytes"].as_u64().unwrap() > 0);
        let sent = p["sent_bytes_per_iteration"].as_f64().unwrap();
        assert!(sent >= frames * frame_bytes && sent < (frames + 0.5) * frame_bytes, "{sent} for {frames} frames of {frame_bytes} bytes");
    }
    assert_eq!(per[0]["frames"][1], per[1]["frames"][0]);
    let summed = r["sensor_rows_summed"].as_u64().unwrap();
    assert!(summed > 0 && summed <= 8, "{summed} of 64 rows summed");
}

#[test]
fn a_wrong_stored_lipschitz_constant_is_measured_again_by_the_ranks() {
    let dir = tempfile::tempdir().unwrap();
    let sim = simulate(dir.path(), "dual");
    let s = |f: &str| sim.join(f).display().to_string();
    let (raw, psf, cfg) = (s("raw.tiff"), s("psf.tiff"), s("capture.toml"));
    let cache = dir.path().join("cache-wrong");
    let args = |out: &Path| -> Vec<String> {
        ["reconstruct", "--raw", &raw, "--psf", &psf, "--config", &cfg, "--iters", "20", "--full-grid", "--out", out.to_str().unwrap()]
            .iter()
            .map(|a| a.to_string())
            .collect()
    };
    let alone = dir.path().join("alone");
    let a = args(&alone);
    ok(rollcam(&a.iter().map(|s| s.as_str()).collect::<Vec<_>>(), &cache).output().unwrap(), "reconstruct alone");
    let entries: Vec<std::path::PathBuf> = std::fs::read_dir(cache.join("lipschitz")).unwrap().map(|e| e.unwrap().path()).collect();
    let read = |p: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
    let measured: Vec<f64> = entries.iter().map(|p| read(p)["lambda_max"].as_f64().unwrap()).collect();
    // Steps a million million times too long, 10 times too short, 10 times too long:
    // outside the range the ranks check together (a few power iterations, the bound
    // from the PSF and the weights), so measured again before the solve.
    for (i, factor) in [1e-12, 10.0, 0.1].into_iter().enumerate() {
        for (p, &l) in entries.iter().zip(&measured) {
            let mut v = read(p);
            v["lambda_max"] = serde_json::json!(l * factor);
            std::fs::write(p, v.to_string()).unwrap();
        }
        let out = dir.path().join(format!("split{i}"));
        let a = args(&out);
        let text = ok(mpirun(2, &a.iter().map(|s| s.as_str()).collect::<Vec<_>>(), &cache), "mpirun with a wrong stored constant");
        assert!(text.contains("measured again"), "{factor}: {text}");
        let d = rel_diff(&video(&alone), &video(&out));
        assert!(d <= 1e-5, "{factor}: relative difference {d:.3e} from the single process");
        assert_eq!(summary(&out)["channels"][0]["lipschitz_cached"], false);
    }
}

#[test]
fn a_rank_with_more_threads_than_its_cpus_is_warned() {
    let dir = tempfile::tempdir().unwrap();
    let bench = |binding: &str| {
        let mut c = Command::new("mpirun");
        c.args(["--bind-to", binding, "-np", "1", "-x", "RAYON_NUM_THREADS", BIN, "bench", "--preset", "small", "--warmup", "1", "--iters", "1"]);
        c.env("RAYON_NUM_THREADS", "2").env("ROLLCAM_CACHE_DIR", dir.path()).env("OMPI_ALLOW_RUN_AS_ROOT", "1").env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1");
        ok(c.output().unwrap(), &format!("bench --bind-to {binding}"))
    };
    // Bound to one core (Open MPI's default for few ranks), two threads share it.
    let text = bench("core");
    assert!(text.contains("MPI rank 0 has 2 worker threads but may run on 1 CPU(s)") && text.contains("--bind-to none"), "{text}");
    // Unbound, on a machine with two CPUs or more, nothing to say.
    if std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1) >= 2 {
        let text = bench("none");
        assert!(!text.contains("worker threads but may run on"), "{text}");
    }
}
