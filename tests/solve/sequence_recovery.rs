//! Consecutive simulated captures of flashing LEDs reconstructed as one video: the
//! LEDs' time courses follow the truth across the captures (and a wrong offset does
//! not), gap frames are flagged exactly, continuous readout reconstructs better jointly
//! than capture by capture, and a warm start saves iterations.

use rollcam::io::cache::LipschitzCache;
use rollcam::model::capture::{CaptureConfig, Fov};
use rollcam::model::data::DataTerm;
use rollcam::model::prepare::Plane;
use rollcam::model::shutter::ShutterMode;
use rollcam::sim::{self, Consecutive, LedArray, LedLine, LensletParams, NoiseModel, Scene, SequenceSimulation};
use rollcam::solve::optimize::{Device, IterInfo, StopRule};
use rollcam::solve::problem::{SolveParams, SolveSettings};
use rollcam::solve::reconstruct::Hooks;
use rollcam::solve::sequence::{Sequence, SequenceVideo, TimeGrid, TimeSource};
use rollcam::solve::trace::compare;
use std::sync::atomic::AtomicBool;

use crate::support::common::correlation;

const ROWS: usize = 32;
const COLS: usize = 40;

struct Case {
    cfg: CaptureConfig,
    psf: Vec<f32>,
    leds: LedArray,
    sim: SequenceSimulation,
}

/// Dual shutter, 32 x 40, T_l = 100 us, T_e = 300 us: K = 16 + 3 - 1 = 18 frames of
/// 100 us per capture. Two LEDs flashing 1300 us and 900 us square waves.
fn simulate(captures: usize, period_us: f64) -> Case {
    simulate_with(captures, period_us, 0.0)
}

/// The LEDs in front of a static, smooth background of `background_e_per_us` at its
/// brightest (photo-electrons per microsecond per pixel).
struct Backdrop {
    leds: LedArray,
    background: Vec<f32>,
}

impl Scene for Backdrop {
    fn size(&self) -> (usize, usize) {
        (ROWS, COLS)
    }
    fn integrate(&self, t0_us: f64, t1_us: f64, out: &mut [f32]) {
        self.leds.integrate(t0_us, t1_us, out);
        let dt = (t1_us - t0_us) as f32;
        for (o, b) in out.iter_mut().zip(&self.background) {
            *o += b * dt;
        }
    }
    fn describe(&self) -> toml::Table {
        self.leds.describe()
    }
}

fn simulate_with(captures: usize, period_us: f64, background_e_per_us: f32) -> Case {
    let cfg = CaptureConfig::new(ROWS, COLS, 100.0, 300.0, ShutterMode::Dual);
    let psf: Vec<f32> =
        sim::lenslet_psf(ROWS, COLS, &LensletParams { aperture_fraction: 1.0, ..LensletParams::default() }, 3).unwrap().iter().cloned().collect();
    let leds = LedArray::new(
        ROWS,
        COLS,
        LedLine { leds: 2, spacing_px: 12.0, radius_px: 1.5, period_us: vec![1300.0, 900.0], duty: 0.5, phase_us: vec![0.0], e_per_us: 2000.0 },
    )
    .unwrap();
    let background: Vec<f32> = (0..ROWS * COLS)
        .map(|i| {
            let (r, c) = ((i / COLS) as f32, (i % COLS) as f32);
            background_e_per_us * (-((r - 10.0).powi(2) + (c - 14.0).powi(2)) / 60.0).exp()
        })
        .collect();
    let scene = Backdrop { leds: leds.clone(), background };
    let sim = sim::simulate_sequence(&cfg, &psf, &scene, &NoiseModel::noise_free(), 4, 1, Consecutive { captures, period_us }).unwrap();
    Case { cfg, psf, leds, sim }
}

fn sequence(case: &Case, grid: TimeGrid) -> Sequence {
    let psf = Plane { rows: ROWS, cols: COLS, data: case.psf.clone() };
    let raws = case.sim.raws.iter().map(|r| Plane { rows: ROWS, cols: COLS, data: r.iter().map(|v| v - 100.0).collect() }).collect();
    Sequence::new(&case.cfg, case.cfg.timing().weights().unwrap(), psf, grid, raws)
}

fn params(seq: &Sequence, iters: usize) -> SolveParams {
    // The weight these comparisons were measured at, and exactly `iters` iterations.
    SolveSettings { iters, tau: rollcam::solve::tau::Tau::Relative(2e-3), obj_tol: 0.0, ..SolveSettings::default() }
        .validate()
        .unwrap()
        .resolve(seq, Fov::Sensor)
}

/// `p` with another stop rule.
fn stopping(p: &SolveParams, stop: StopRule) -> SolveParams {
    let mut q = p.clone();
    q.stop = stop;
    q
}

fn hooks_run<T>(f: impl FnOnce(&Hooks) -> T) -> T {
    let stop = AtomicBool::new(false);
    let on_row = |_: usize, _: &rollcam::solve::trace::TraceRow| {};
    f(&Hooks { on_row: &on_row, stop: &stop })
}

/// Light of LED `led` in every frame of a `(frames, ROWS, COLS)` video: a 3 x 3 sum
/// around its centre.
fn led_course(video: &[f32], frames: usize, leds: &LedArray, led: usize) -> Vec<f64> {
    let (r, c) = leds.centre_px(led);
    let (r, c) = (r.floor() as usize, c.floor() as usize);
    (0..frames)
        .map(|f| {
            let mut s = 0.0;
            for i in r - 1..=r + 1 {
                for j in c - 1..=c + 1 {
                    s += video[(f * ROWS + i) * COLS + j] as f64;
                }
            }
            s
        })
        .collect()
}

/// Each LED's correlation with the truth over the true grid's covered frames (those a
/// reconstruction of `rec_frames` frames holds).
fn led_correlations(case: &Case, truth_grid: &TimeGrid, rec: &SequenceVideo) -> Vec<f64> {
    let truth: Vec<f32> = case.sim.truth.iter().cloned().collect();
    let tf = case.sim.truth.dim().0;
    let frames: Vec<usize> = (0..tf.min(rec.shape.0)).filter(|&f| truth_grid.coverage[f] > 0.0).collect();
    (0..case.leds.leds())
        .map(|led| {
            let t = led_course(&truth, tf, &case.leds, led);
            let r = led_course(&rec.video, rec.shape.0, &case.leds, led);
            let (a, b): (Vec<f64>, Vec<f64>) = frames.iter().map(|&f| (r[f], t[f])).unzip();
            correlation(&a, &b)
        })
        .collect()
}

#[test]
fn gaps_are_flagged_and_led_time_courses_follow_the_truth_across_captures() {
    // Captures 2000 us apart: offsets 0, 20, 40 frames; each covers 18, so frames
    // 18, 19 and 38, 39 are gaps; 40 + 18 = 58 frames in all.
    let case = simulate(3, 2000.0);
    let w = case.cfg.timing().weights().unwrap();
    let grid = TimeGrid::new(&case.sim.start_us, &w, TimeSource::DeviceTimestamps).unwrap();
    assert_eq!(grid.capture_frames, 18);
    assert_eq!(grid.offsets, vec![0, 20, 40]);
    assert_eq!(grid.frames, 58);
    assert_eq!(case.sim.truth.dim(), (58, ROWS, COLS));
    assert_eq!(grid.gap_frames(), vec![18, 19, 38, 39]);
    assert!(grid.shared_frames().is_empty());
    assert!(grid.coverage.iter().enumerate().all(|(f, &c)| (c == 0.0) == [18, 19, 38, 39].contains(&f)));

    let seq = sequence(&case, grid.clone());
    let p = params(&seq, 300);
    let truth: Vec<f32> = case.sim.truth.iter().cloned().collect();
    let rec = hooks_run(|h| seq.solve_joint(&p, Some((&truth, "truth")), &LipschitzCache::disabled(), h, u64::MAX)).unwrap();
    let good = led_correlations(&case, &grid, &rec);

    // The same raws placed 3 frames too early each (as from a wrong frame period).
    let wrong = TimeGrid::with_offsets(&[0, 17, 34], &w, TimeSource::FramePeriod { period_us: 1700.0 });
    let seq_w = sequence(&case, wrong);
    let rec_w = hooks_run(|h| seq_w.solve_joint(&p, None, &LipschitzCache::disabled(), h, u64::MAX)).unwrap();
    let bad = led_correlations(&case, &grid, &rec_w);
    eprintln!("LED correlations: right offsets {good:?}, wrong offsets {bad:?}; PSNR {:.2} dB", rec.error.unwrap().psnr_db);
    for led in 0..2 {
        assert!(good[led] > 0.85, "LED {led}: correlation {:.3} with the truth", good[led]);
        assert!(bad[led] < 0.85 && bad[led] < good[led] - 0.15, "LED {led}: a wrong offset still correlates {:.3} (right: {:.3})", bad[led], good[led]);
    }
}

#[test]
fn continuous_readout_is_one_time_course_better_than_separate_captures() {
    // Continuous readout: the next capture starts as the last row pair starts, 1600 us
    // later; captures 16 frames apart, each 18 long: frames 16, 17, 32, 33 shared.
    let case = simulate(3, sim::readout_period_us(&CaptureConfig::new(ROWS, COLS, 100.0, 300.0, ShutterMode::Dual)));
    let w = case.cfg.timing().weights().unwrap();
    let grid = TimeGrid::new(&case.sim.start_us, &w, TimeSource::DeviceTimestamps).unwrap();
    assert_eq!(grid.offsets, vec![0, 16, 32]);
    assert_eq!(grid.shared_frames(), vec![16, 17, 32, 33]);
    assert!(grid.gap_frames().is_empty());
    let seq = sequence(&case, grid.clone());
    // Both solved to convergence (the objective stops falling by ~150 iterations).
    let p = params(&seq, 1000);
    let truth: Vec<f32> = case.sim.truth.iter().cloned().collect();
    let t = Some((truth.as_slice(), "truth"));
    let joint = hooks_run(|h| seq.solve_joint(&p, t, &LipschitzCache::disabled(), h, u64::MAX)).unwrap();
    let separate = hooks_run(|h| seq.solve_separate(&p, t, &LipschitzCache::disabled(), h)).unwrap();
    let streaming = hooks_run(|h| seq.solve_streaming(&p, 4, true, t, &LipschitzCache::disabled(), h)).unwrap();
    // Around the boundaries: frames 12..22 and 28..38.
    let fl = ROWS * COLS;
    let boundary = |v: &[f32]| -> f64 {
        let pick = |x: &[f32]| -> Vec<f32> { [12..22, 28..38].iter().flat_map(|r| x[r.start * fl..r.end * fl].to_vec()).collect() };
        compare(&pick(v), &pick(&truth)).unwrap().psnr_db
    };
    let (pj, ps, pst) = (joint.error.unwrap().psnr_db, separate.error.unwrap().psnr_db, streaming.error.unwrap().psnr_db);
    let (bj, bs) = (boundary(&joint.video), boundary(&separate.video));
    let cj = led_correlations(&case, &grid, &joint);
    let cs = led_correlations(&case, &grid, &separate);
    eprintln!("PSNR joint {pj:.2} dB, separate {ps:.2} dB, streaming {pst:.2} dB; at the boundaries joint {bj:.2}, separate {bs:.2}; LED correlations joint {cj:?}, separate {cs:?}");
    assert!(pj > ps + 0.2, "joint {pj:.2} dB vs separate {ps:.2} dB");
    assert!(bj > bs + 0.5, "boundary frames: joint {bj:.2} dB vs separate {bs:.2} dB");
    for led in 0..2 {
        assert!(cj[led] > 0.85 && cj[led] >= cs[led], "LED {led}: joint {:.3}, separate {:.3}", cj[led], cs[led]);
    }
    // Streaming sits with the joint solve, above the separate one.
    assert!(pst > ps, "streaming {pst:.2} dB vs separate {ps:.2} dB");
}

#[test]
fn warm_start_reaches_the_objective_in_fewer_iterations() {
    let case = simulate_with(2, 1600.0, 30.0);
    let w = case.cfg.timing().weights().unwrap();
    let grid = TimeGrid::new(&case.sim.start_us, &w, TimeSource::DeviceTimestamps).unwrap();
    let seq = sequence(&case, grid.clone());
    let p = params(&seq, 300);
    let cache = LipschitzCache::disabled();
    let (f, mv, nv) = seq.video_shape();
    let fl = mv * nv;
    // Capture 0 solved; capture 1's window over 4 frames of it.
    let mut x = vec![0.0f32; f * fl];
    let w0 = seq.window(0, 0, 4, &x);
    let (x0, _) = hooks_run(|h| seq.solve_window(&w0, None, &p, None, &cache, h).unwrap());
    x[w0.frames.start * fl..w0.frames.end * fl].copy_from_slice(&x0);
    let solved_end = w0.frames.end;
    let w1 = seq.window(1, solved_end, 4, &x);
    assert_eq!(w1.frames, 12..34);
    assert_eq!(w1.captures, vec![0, 1]);
    // From zero: the objective after 50 iterations is the target.
    let cold = hooks_run(|h| seq.solve_window(&w1, None, &stopping(&p, StopRule::iterations(50)), None, &cache, h).unwrap()).1;
    let target = cold.trace.last().unwrap().objective;
    // Warm: iterations until the objective is at or below the target.
    let warm_x0 = seq.warm_start(&w1, solved_end, &x);
    let mut reached = None;
    let mut obs = |i: &IterInfo| {
        if i.objective() <= target {
            reached = Some(i.iteration);
            false
        } else {
            true
        }
    };
    let tv = rollcam::solve::prox::TotalVariation::new((w1.frames.len(), mv, nv), p.tau, p.alpha);
    let l = cold.stats.lipschitz;
    let fista =
        rollcam::solve::optimize::Fista { lipschitz: l, stop: StopRule::iterations(50), restart: Some(rollcam::solve::optimize::RestartTest::Objective) };
    let _ = fista.solve(&w1.op, &DataTerm::new(&w1.b).with_lower_bounds(w1.lower_bounds.as_deref()), &tv, Some(warm_x0.clone()), &mut obs);
    let warm = reached.expect("the warm start reaches the cold solve's 50-iteration objective within 50 iterations");
    // The same through the library's window solve: its first objective is lower.
    let (_, rep) = hooks_run(|h| seq.solve_window(&w1, Some(warm_x0), &stopping(&p, StopRule::iterations(1)), None, &cache, h).unwrap());
    eprintln!(
        "iterations to the objective {target:.4e}: from zero 50, warm-started {warm}; first objective warm {:.4e} vs cold {:.4e}",
        rep.stats.objective, cold.trace[0].objective
    );
    assert!(warm <= 42, "warm start needed {warm} iterations, from zero 50");
    assert!(rep.warm_start && rep.stats.objective < cold.trace[0].objective);
}

#[test]
fn captures_pushed_one_by_one_give_the_streaming_video() {
    use rollcam::solve::sequence::{StreamWindows, Streamer};
    let case = simulate(3, 1600.0);
    let w = case.cfg.timing().weights().unwrap();
    let grid = TimeGrid::new(&case.sim.start_us, &w, TimeSource::DeviceTimestamps).unwrap();
    let seq = sequence(&case, grid);
    let p = params(&seq, 60);
    let cache = LipschitzCache::disabled();
    let whole = hooks_run(|h| seq.solve_streaming(&p, 4, true, None, &cache, h)).unwrap();
    let psf = Plane { rows: ROWS, cols: COLS, data: case.psf.clone() };
    let windows = StreamWindows { overlap: 4, warm: true };
    let mut streamer = Streamer::new(&case.cfg, w.clone(), psf, p.clone(), windows, TimeSource::DeviceTimestamps, &cache);
    let fl = ROWS * COLS;
    let mut finals = Vec::new();
    let mut snapshots = Vec::new();
    for (c, raw) in case.sim.raws.iter().enumerate() {
        let plane = Plane { rows: ROWS, cols: COLS, data: raw.iter().map(|v| v - 100.0).collect() };
        // Any clock: the starts are shifted by a constant.
        let step = hooks_run(|h| streamer.push(plane, Default::default(), 5e6 + case.sim.start_us[c], h)).unwrap();
        assert_eq!(step.report.warm_start, c > 0);
        finals.push(step.final_frames.clone());
        snapshots.push(streamer.video()[..step.final_frames.end * fl].to_vec());
    }
    // Offsets 0, 16, 32; overlap 4: windows start at 0, 12, 28, so frames before
    // min(o_c + 1, solved end) - 4 are final.
    assert_eq!(finals, vec![0..0, 0..13, 0..29]);
    let video = streamer.finish();
    assert_eq!(video.shape, whole.shape);
    assert_eq!(video.video, whole.video, "pushed one by one must equal the streaming solve");
    for s in &snapshots {
        assert_eq!(&video.video[..s.len()], &s[..], "frames said final changed later");
    }
    // A capture too close to the previous one is refused.
    let mut streamer = Streamer::new(&case.cfg, w, Plane { rows: ROWS, cols: COLS, data: case.psf.clone() }, p, windows, TimeSource::DeviceTimestamps, &cache);
    let plane = || Plane { rows: ROWS, cols: COLS, data: vec![0.0; ROWS * COLS] };
    hooks_run(|h| streamer.push(plane(), Default::default(), 0.0, h)).unwrap();
    let e = hooks_run(|h| streamer.push(plane(), Default::default(), 50.0, h)).err().unwrap().to_string();
    assert!(e.contains("capture 1 start") && e.contains("one video frame time"), "{e}");
}

/// Consecutive captures are solved on the CPU: a window asked for on a CUDA device is
/// refused by name before its solve, whether or not a device is here.
#[test]
fn a_sequence_window_refuses_the_cuda_device_by_name() {
    let case = simulate_with(2, 1600.0, 30.0);
    let w = case.cfg.timing().weights().unwrap();
    let grid = TimeGrid::new(&case.sim.start_us, &w, TimeSource::DeviceTimestamps).unwrap();
    let seq = sequence(&case, grid);
    let mut p = params(&seq, 5);
    p.device = Device::Cuda;
    let (f, mv, nv) = seq.video_shape();
    let x = vec![0.0f32; f * mv * nv];
    let w0 = seq.window(0, 0, 4, &x);
    let e = hooks_run(|h| seq.solve_window(&w0, None, &p, None, &LipschitzCache::disabled(), h)).unwrap_err().to_string();
    assert!(e.contains("consecutive captures are solved on the CPU") && e.contains("--device cuda"), "{e}");
}
