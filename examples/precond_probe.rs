//! Probe: per-frame diagonal preconditioning and the still start for FISTA with
//! restart on a capture folder written by `rollcam simulate` (raw.tiff, psf.tiff,
//! capture.toml, truth.npy). Prints iterations and seconds to within 1% / 0.1% of the
//! best objective and to the best relative error + 1%.
//!
//!     cargo run --release --example precond_probe -- DIR [ITERS] [STILL_ITERS,..] [precond]
use ndarray::Axis;
use rayon::prelude::*;
use rollcam::io::cache::LipschitzCache;
use rollcam::model::capture::CaptureOverrides;
use rollcam::model::data::DataTerm;
use rollcam::model::op::Operator;
use rollcam::model::prepare::{prepare, SensorInput};
use rollcam::solve::lipschitz::power_iteration;
use rollcam::solve::optimize::{solve, Fista, IterInfo, OptimizerSettings, SolverKind, StopRule};
use rollcam::solve::problem::{Problem, ValidSettings};
use rollcam::solve::prox::Prox;
use rollcam::solve::prox::TotalVariation;
use rollcam::solve::trace::compare;
use std::path::Path;

/// `A P^{-1/2}`: frame k of the input scaled by `1/sqrt(p_k)`.
struct Scaled<'a, A: ?Sized> {
    inner: &'a A,
    inv_sqrt: Vec<f32>,
    frame: usize,
}

impl<A: Operator + ?Sized> Operator for Scaled<'_, A> {
    fn input_shape(&self) -> Vec<usize> {
        self.inner.input_shape()
    }
    fn output_shape(&self) -> Vec<usize> {
        self.inner.output_shape()
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        let mut v = x.to_vec();
        v.par_chunks_mut(self.frame).zip(&self.inv_sqrt).for_each(|(f, &s)| f.iter_mut().for_each(|a| *a *= s));
        self.inner.forward(&v, y);
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        self.inner.adjoint(y, x);
        x.par_chunks_mut(self.frame).zip(&self.inv_sqrt).for_each(|(f, &s)| f.iter_mut().for_each(|a| *a *= s));
    }
}

/// TV of `P^{-1/2} z` with the parallel-proximal Haar map in the metric `P`.
struct WeightedHaar {
    tv: TotalVariation,
    p: Vec<f32>,
}

impl WeightedHaar {
    fn video(&self, z: &[f32]) -> Vec<f32> {
        let fl = self.tv.shape.1 * self.tv.shape.2;
        let mut v = z.to_vec();
        v.par_chunks_mut(fl).zip(&self.p).for_each(|(f, &p)| {
            let s = 1.0 / p.sqrt();
            f.iter_mut().for_each(|a| *a *= s)
        });
        v
    }
}

fn clip(d: f32, c: f32) -> f32 {
    d.max(-c).min(c)
}

impl Prox for WeightedHaar {
    fn value(&self, z: &[f32]) -> f64 {
        self.tv.value(&self.video(z))
    }
    fn prox(&self, z: &[f32], gamma: f32, out: &mut [f32]) {
        let (k, m, n) = self.tv.shape;
        let fl = m * n;
        let u = self.video(z);
        let j = 6.0f32;
        let c = [j * gamma * self.tv.tau * self.tv.weights[0], j * gamma * self.tv.tau * self.tv.weights[1], j * gamma * self.tv.tau * self.tv.weights[2]];
        let p = &self.p;
        out.par_chunks_mut(fl).enumerate().for_each(|(f, o)| {
            let uf = &u[f * fl..(f + 1) * fl];
            let pf = p[f];
            let (cy, cx) = (c[1] / pf, c[2] / pf);
            for r in 0..m {
                for q in 0..n {
                    let i = r * n + q;
                    let v = uf[i];
                    let mut acc = 0.0f32;
                    if q + 1 < n {
                        acc += clip((uf[i + 1] - v) / 2.0, cx);
                    }
                    if q > 0 {
                        acc -= clip((v - uf[i - 1]) / 2.0, cx);
                    }
                    if r + 1 < m {
                        acc += clip((uf[i + n] - v) / 2.0, cy);
                    }
                    if r > 0 {
                        acc -= clip((v - uf[i - n]) / 2.0, cy);
                    }
                    if f + 1 < k {
                        let pn = p[f + 1];
                        let d = u[(f + 1) * fl + i] - v;
                        acc += clip(d / (1.0 / pf + 1.0 / pn), c[0]) / pf;
                    }
                    if f > 0 {
                        let pp = p[f - 1];
                        let d = v - u[(f - 1) * fl + i];
                        acc -= clip(d / (1.0 / pf + 1.0 / pp), c[0]) / pf;
                    }
                    o[i] = (v + acc / j).max(0.0) * pf.sqrt();
                }
            }
        });
    }
}

type Row = (f64, f64, f64, usize); // seconds, objective, rel error, iteration

fn report(label: &str, rows: &[Row], best_obj: f64, best_err: f64) {
    let at = |f: &dyn Fn(&Row) -> bool| rows.iter().find(|r| f(r)).map(|r| format!("{} it / {:.1} s", r.3, r.0)).unwrap_or("-".into());
    println!(
        "{label:>28}: obj 1%: {:>16}  obj 0.1%: {:>16}  err+1%: {:>16}  final err {:.4} obj {:.5e}",
        at(&|r| r.1 <= best_obj * 1.01),
        at(&|r| r.1 <= best_obj * 1.001),
        at(&|r| r.2 <= best_err * 1.01),
        rows.last().unwrap().2,
        rows.last().unwrap().1
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = Path::new(&args[1]);
    let iters: usize = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(300);
    let still_iters: Vec<usize> = args.get(3).map(|s| s.split(',').map(|v| v.parse().unwrap()).collect()).unwrap_or(vec![30, 100]);
    let precond = args.get(4).is_some_and(|s| s == "precond");
    let betas = [0.5f32, 1.0];
    let raw = rollcam::io::read_image(dir.join("raw.tiff")).unwrap();
    let psf = rollcam::io::read_image(dir.join("psf.tiff")).unwrap();
    let (rows, cols, _) = raw.dim();
    let cfg = rollcam::io::capture_file::resolve_capture(Some(&dir.join("capture.toml")), &CaptureOverrides::default(), (rows, cols)).unwrap();
    let truth4 = rollcam::io::read_truth(dir.join("truth.npy")).unwrap();
    let truth: Vec<f32> = truth4.index_axis(Axis(3), 0).iter().cloned().collect();
    let prepared = prepare(raw.view(), "raw", psf.view(), "psf", &cfg, &SensorInput::default()).unwrap();
    let cache = LipschitzCache::disabled();
    let problem = Problem::new(&prepared, &cfg, cfg.fov).unwrap();
    let params = ValidSettings::default().resolve(&problem, problem.fov);
    let model = problem.model(0);
    let (k, m, n) = model.video_shape();
    assert_eq!(truth.len(), k * m * n, "truth shape");
    let b = &prepared.raw[0].data;
    let tv = TotalVariation::new((k, m, n), params.tau, params.alpha);
    let (l, _) = problem.lipschitz(0, &cache);
    println!("{k} x {m} x {n}, tau {:.4}, L {l:.4e}, tv_prox {:?}", params.tau, params.tv_prox.resolve(&tv, problem.atb_max(0) as f64));
    let mut all: Vec<(String, Vec<Row>)> = Vec::new();

    // Baseline: the library's fista-restart with the default map.
    let run_lib = |x0: Option<Vec<f32>>, t0: f64| {
        let st = OptimizerSettings::new(SolverKind::FistaRestart, l, StopRule::iterations(iters));
        let prior = params.tv_prox.resolve(&tv, problem.atb_max(0) as f64).build(&tv);
        let mut rows = Vec::new();
        let mut obs = |i: &IterInfo| {
            rows.push((t0 + i.seconds, i.objective(), compare(i.x, &truth).expect("a simulated truth has light").rel_error, i.iteration));
            true
        };
        solve(&st, model, &DataTerm::new(b), prior.as_ref(), x0, &mut obs);
        rows
    };
    all.push(("fista-restart".into(), run_lib(None, 0.0)));

    // Still warm start: the still image solved (one convolution per call), repeated.
    let still = rollcam::model::still::Still::new(model);
    let still_tv = TotalVariation::new((1, m, n), rollcam::solve::tau::static_frame_tau(params.tau, k), params.alpha);
    let t = std::time::Instant::now();
    let ls = power_iteration(&still, 60, 1e-4, 1).lambda_max * 1.01;
    let tl = t.elapsed().as_secs_f64();
    for s_iters in still_iters.clone() {
        let st = OptimizerSettings::new(SolverKind::FistaRestart, ls, StopRule::iterations(s_iters));
        let prior = params.tv_prox.resolve(&still_tv, problem.atb_max(0) as f64).build(&still_tv);
        let r = solve(&st, &still, &DataTerm::new(b), prior.as_ref(), None, &mut rollcam::solve::optimize::NoObserver);
        let x0 = r.x.repeat(k);
        println!(
            "still: {} iterations, {:.2} s (+{tl:.2} s Lipschitz), start rel error {:.4}",
            r.iterations,
            r.seconds,
            compare(&x0, &truth).expect("a simulated truth has light").rel_error
        );
        all.push((format!("still {s_iters} + fista-restart"), run_lib(Some(x0), r.seconds + tl)));
    }
    if !precond {
        return finish(all);
    }

    // Per-frame preconditioner p_k = (sensitivity_k / max)^beta.
    let sens = model.frame_sensitivity(&prepared.psf[0].data);
    let smax = sens.iter().cloned().fold(0.0, f64::max);
    println!("sensitivity min/max {:.3}", sens.iter().cloned().fold(f64::MAX, f64::min) / smax);
    for &beta in &betas {
        let p: Vec<f32> = sens.iter().map(|s| ((s / smax).max(1e-3) as f32).powf(beta)).collect();
        let op = Scaled { inner: model, inv_sqrt: p.iter().map(|v| 1.0 / v.sqrt()).collect(), frame: m * n };
        let t = std::time::Instant::now();
        let lp = power_iteration(&op, 60, 1e-4, 1).lambda_max * 1.01;
        let tl = t.elapsed().as_secs_f64();
        println!("beta {beta}: L' {lp:.4e} ({tl:.2} s)");
        let reg = WeightedHaar { tv: tv.clone(), p: p.clone() };
        let fista = Fista { lipschitz: lp, stop: StopRule::iterations(iters), restart: true };
        let mut rows = Vec::new();
        let mut obs = |i: &IterInfo| {
            rows.push((i.seconds, i.objective(), compare(&reg.video(i.x), &truth).expect("a simulated truth has light").rel_error, i.iteration));
            true
        };
        fista.solve(&op, &DataTerm::new(b), &reg, None, &mut obs);
        all.push((format!("precond beta {beta}"), rows));
    }
    // Unit weights through the probe's own map: the cost of this map against the library's.
    {
        let p = vec![1.0f32; k];
        let op = Scaled { inner: model, inv_sqrt: p.clone(), frame: m * n };
        let reg = WeightedHaar { tv: tv.clone(), p };
        let fista = Fista { lipschitz: l, stop: StopRule::iterations(iters), restart: true };
        let mut rows = Vec::new();
        let mut obs = |i: &IterInfo| {
            rows.push((i.seconds, i.objective(), compare(&reg.video(i.x), &truth).expect("a simulated truth has light").rel_error, i.iteration));
            true
        };
        fista.solve(&op, &DataTerm::new(b), &reg, None, &mut obs);
        all.push(("probe map, unit weights".into(), rows));
    }
    finish(all)
}

fn finish(all: Vec<(String, Vec<Row>)>) {
    let best_obj = all.iter().flat_map(|(_, r)| r.iter().map(|r| r.1)).fold(f64::MAX, f64::min);
    let best_err = all.iter().flat_map(|(_, r)| r.iter().map(|r| r.2)).fold(f64::MAX, f64::min);
    println!("best objective {best_obj:.5e}, best rel error {best_err:.4}");
    for (label, rows) in &all {
        report(label, rows, best_obj, best_err);
    }
}
