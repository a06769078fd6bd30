//! `rollcam simulate --keyframes` through the real binary: key frames of a second,
//! global-shutter camera written beside the raw, their `[[keyframes]]` tables, the
//! refusals of bad times; and the occluder scene.

use crate::support::cli;

use cli::{fails, ok, rollcam};
use ndarray::{Array2, Array3, Axis};
use rollcam::model::capture::CaptureConfig;
use rollcam::model::keyframe::{Kernel, KeyFrameOp};
use rollcam::model::op::Operator;
use std::path::{Path, PathBuf};

const ROWS: usize = 48;
const COLS: usize = 64;

/// `simulate --scene SCENE` of a 48 x 64 sensor into `dir/name` with `extra` flags.
fn simulate(dir: &Path, name: &str, scene: &str, extra: &[&str]) -> (PathBuf, String) {
    let out = dir.join(name);
    let size = [ROWS.to_string(), COLS.to_string()];
    let mut args = vec!["simulate", "--scene", scene, "--rows", &size[0], "--cols", &size[1], "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let stdout = ok(&rollcam(&args, dir));
    (out, stdout)
}

fn truth(out: &Path) -> Array3<f32> {
    rollcam::io::read_truth(out.join("truth.npy")).unwrap().index_axis_move(Axis(3), 0)
}

fn grey(path: &Path) -> Array2<f32> {
    rollcam::io::read_image(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).index_axis_move(Axis(2), 0)
}

fn simulation(cfg: &CaptureConfig) -> &toml::Table {
    cfg.simulation.as_ref().unwrap()["keyframes"].as_table().unwrap()
}

/// `K_j v` of table `j` of `cfg` for the video `v`, with the key frame's size `key`
/// and the lens blur read from its file.
fn expected(out: &Path, cfg: &CaptureConfig, j: usize, v: &Array3<f32>, key: (usize, usize)) -> Vec<f32> {
    let r = &cfg.keyframes[j];
    let w = r.time_weights(v.dim().0, cfg.timing().frame_time_us()).unwrap();
    let blur = r.psf.as_ref().map(|p| {
        let img = grey(&out.join(p));
        Kernel::from_image(img.as_slice().unwrap(), img.nrows(), img.ncols()).unwrap()
    });
    let op = KeyFrameOp::new(v.dim(), key, w, r.affine, blur);
    let mut y = vec![0.0f32; key.0 * key.1];
    op.forward(v.as_slice().unwrap(), &mut y);
    y
}

#[test]
fn first_and_last_key_frames_are_the_map_of_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (out, stdout) = simulate(dir.path(), "dense", "disc-over-texture", &["--keyframes", "first,last", "--keyframe-noise", "0"]);
    assert!(stdout.contains("key frames: 2 of 48 x 64"), "{stdout}");
    let cfg = CaptureConfig::load(&out.join("capture.toml")).unwrap();
    let v = truth(&out);
    let (frames, tf) = (v.dim().0, cfg.timing().frame_time_us());
    assert_eq!(cfg.keyframes.len(), 2);
    // The windows: one frame time at the first and at the last frame's start.
    assert_eq!((cfg.keyframes[0].start_us, cfg.keyframes[0].exposure_us), (0.0, tf));
    assert!((cfg.keyframes[1].start_us - (frames - 1) as f64 * tf).abs() < 1e-6 * tf);
    let w = cfg.keyframes[1].time_weights(frames, tf).unwrap();
    assert!((w[frames - 1] - 1.0).abs() < 1e-6 && w[..frames - 1].iter().all(|&x| x.abs() < 1e-6), "{w:?}");
    // The gain is provenance, not in the tables; the dark level is, and differs from the raw's.
    assert!(cfg.keyframes.iter().all(|k| k.gain.is_none() && k.dark_level == Some(64.0) && k.affine.is_none() && k.psf.is_none()));
    assert_ne!(cfg.dark_level, Some(64.0));
    let gain = simulation(&cfg)["gain"].as_float().unwrap();
    assert_eq!(simulation(&cfg)["gain_in_tables"].as_bool(), Some(false));
    let mut peak = 0.0f32;
    for j in 0..2 {
        let path = out.join(&cfg.keyframes[j].file);
        assert_eq!(path.file_name().unwrap().to_str().unwrap(), format!("keyframe_{j:03}.tiff"));
        assert_eq!(tiff_bits(&path), 16, "{}", path.display());
        let img = grey(&path);
        assert_eq!(img.dim(), (ROWS, COLS));
        let y = expected(&out, &cfg, j, &v, (ROWS, COLS));
        // Noise-free: (frame - dark) / gain is the map of the truth up to the rounding.
        for (&got, &e) in img.iter().zip(&y) {
            assert!(((got as f64 - 64.0) / gain - e as f64).abs() <= 0.5 / gain + 1e-6 * e as f64, "{got} vs {e}");
        }
        peak = img.iter().fold(peak, |m, &x| m.max(x));
    }
    // The default gain puts the brightest pixel at 40% of the 16-bit range.
    assert!(((peak as f64 - 64.0) / 65535.0 - 0.4).abs() < 0.01, "{peak}");
    // The two key frames differ: the disc moved.
    assert_ne!(grey(&out.join("keyframe_000.tiff")), grey(&out.join("keyframe_001.tiff")));
}

/// The bits per sample of a TIFF's first page.
fn tiff_bits(path: &Path) -> u16 {
    let bytes = std::fs::read(path).unwrap();
    let le = &bytes[..2] == b"II";
    let u16_at = |i: usize| if le { u16::from_le_bytes([bytes[i], bytes[i + 1]]) } else { u16::from_be_bytes([bytes[i], bytes[i + 1]]) };
    let u32_at = |i: usize| {
        let b = [bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]];
        if le {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        }
    };
    let ifd = u32_at(4) as usize;
    (0..u16_at(ifd) as usize).map(|e| ifd + 2 + 12 * e).find(|&at| u16_at(at) == 258).map(|at| u16_at(at + 8)).expect("a BitsPerSample tag")
}

#[test]
fn noisy_shifted_blurred_and_scaled_key_frames_follow_their_tables() {
    let dir = tempfile::tempdir().unwrap();
    let flags = [
        "--keyframes",
        "first,1000",
        "--keyframe-exposure-us",
        "500",
        "--keyframe-blur-px",
        "1.5",
        "--keyframe-offset-px",
        "-2,3",
        "--keyframe-scale",
        "0.5",
        "--keyframe-noise",
        "3",
        "--keyframe-gain",
        "3",
        "--keyframe-dark-level-adu",
        "200",
        "--keyframe-write-gain",
    ];
    let (out, _) = simulate(dir.path(), "shifted", "occluder", &flags);
    let cfg = CaptureConfig::load(&out.join("capture.toml")).unwrap();
    let key = (ROWS / 2, COLS / 2);
    let affine = [[0.5, 0.0, -0.25 - 2.0], [0.0, 0.5, -0.25 + 3.0]];
    for k in &cfg.keyframes {
        assert_eq!((k.gain, k.dark_level, k.affine, k.psf.as_deref(), k.exposure_us), (Some(3.0), Some(200.0), Some(affine), Some("keyframe_psf.tiff"), 500.0));
    }
    assert_eq!(cfg.keyframes[1].start_us, 1000.0);
    let psf = grey(&out.join("keyframe_psf.tiff"));
    assert_eq!(psf.dim(), (11, 11));
    assert!((psf.sum() - 1.0).abs() < 1e-4 && psf[[5, 5]] == psf.iter().fold(0.0f32, |m, &x| m.max(x)));
    let v = truth(&out);
    assert_eq!(simulation(&cfg)["saturated_pixels"].as_integer(), Some(0));
    // Shot noise (0.5 counts per e-) plus 3 counts of read noise around 3 K v + 200:
    // the residual over the expected variance is about 1 with the table's map, far
    // above it without the shift.
    let unshifted =
        CaptureConfig { keyframes: cfg.keyframes.iter().map(|k| rollcam::model::keyframe::KeyFrameRef { affine: None, ..k.clone() }).collect(), ..cfg.clone() };
    for j in 0..2 {
        let img = grey(&out.join(&cfg.keyframes[j].file));
        assert_eq!(img.dim(), key);
        let chi2 = |cfg: &CaptureConfig| -> f64 {
            let y = expected(&out, cfg, j, &v, key);
            let terms = img.iter().zip(&y).map(|(&got, &e)| {
                let mean = 3.0 * e as f64 + 200.0;
                (got as f64 - mean).powi(2) / (0.5 * (mean - 200.0) + 9.0 + 1.0 / 12.0)
            });
            terms.sum::<f64>() / img.len() as f64
        };
        let (with, without) = (chi2(&cfg), chi2(&unshifted));
        assert!((with - 1.0).abs() < 0.2, "key frame {j}: residual variance / expected {with}");
        assert!(without > 3.0, "key frame {j}: the unshifted map fits too ({without})");
    }
}

#[test]
fn bad_key_frame_times_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bad");
    let o = out.to_str().unwrap();
    let base = ["simulate", "--scene", "moving-disc", "--rows", "48", "--cols", "64", "--out", o];
    let refuse = |extra: &[&str]| -> String {
        let mut args = base.to_vec();
        args.extend_from_slice(extra);
        fails(&rollcam(&args, dir.path()))
    };
    // 48 rows, dual shutter, 220 us lines, 660 us exposure: 26 frames of 220 us.
    let e = refuse(&["--keyframes", "1e30"]);
    assert!(e.contains("--keyframes = 1e30") && e.contains("0 .. 5720 us") && e.contains("26 frames of 220 us"), "{e}");
    let e = refuse(&["--keyframes", "first,nan"]);
    assert!(e.contains("--keyframes = NaN") && e.contains("finite"), "{e}");
    let e = refuse(&["--keyframes", "5600"]);
    assert!(e.contains("--keyframes = 5600") && e.contains("0 .. 5720 us") && e.contains("from 0 to 5500 us"), "{e}");
    let e = refuse(&["--keyframes", "soon"]);
    assert!(e.contains("--keyframes = 'soon'") && e.contains("first or last"), "{e}");
    let e = refuse(&["--keyframes", "last", "--keyframe-exposure-us", "440"]);
    assert!(e.contains("--keyframes = last") && e.contains("from 0 to 5280 us"), "{e}");
    let e = refuse(&["--keyframes", "first", "--keyframe-blur-px", "40"]);
    assert!(e.contains("--keyframe-blur-px = 40"), "{e}");
    let e = refuse(&["--keyframes", "first", "--keyframe-offset-px", "1,2,3"]);
    assert!(e.contains("--keyframe-offset-px") && e.contains("ROW,COL"), "{e}");
    let e = refuse(&["--keyframe-gain", "3"]);
    assert!(e.contains("--keyframes"), "{e}");
    let e = refuse(&["--keyframes", "first", "--captures", "2"]);
    assert!(e.contains("--keyframes") && e.contains("--captures 1"), "{e}");
    assert!(!out.exists(), "a refused simulation wrote {}", out.display());
}

#[test]
fn the_occluder_is_darker_than_its_surroundings_in_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (out, _) = simulate(dir.path(), "occluder", "occluder", &[]);
    let cfg = CaptureConfig::load(&out.join("capture.toml")).unwrap();
    let scene = cfg.scene.as_ref().unwrap();
    assert_eq!(scene["kind"].as_str(), Some("occluder"));
    let radius = scene["radius_px"].as_float().unwrap();
    let start: Vec<f64> = scene["start_px"].as_array().unwrap().iter().map(|x| x.as_float().unwrap()).collect();
    let v = truth(&out);
    // Frame 0: the disc sits at its start; inside it is dark, the ring around it bright.
    let f = v.index_axis(Axis(0), 0);
    let (mut inside, mut ring) = (Vec::new(), Vec::new());
    for ((r, c), &x) in f.indexed_iter() {
        let d = ((r as f64 + 0.5 - start[0]).powi(2) + (c as f64 + 0.5 - start[1]).powi(2)).sqrt();
        if d < radius - 1.5 {
            inside.push(x as f64);
        } else if d > radius + 1.5 && d < 2.0 * radius + 1.5 {
            ring.push(x as f64);
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(!inside.is_empty() && !ring.is_empty());
    assert!(mean(&inside) < 0.2 * mean(&ring), "disc {} vs surroundings {}", mean(&inside), mean(&ring));
    assert!(ring.iter().all(|&x| x > 0.0));
}
