//! FISTA (plain or with adaptive restart) on a CUDA device: the CPU step's arithmetic
//! ([`crate::solve::optimize::fista`]) for one capture's shutter-weighted convolution
//! and the TV prior through the Haar map, with every vector on the device. Per
//! iteration: the adjoint (the residual through the mask and the shutter onto the
//! padded planes, one forward and one inverse batched cuFFT transform) and the forward
//! of the proposal (two more), the Haar map as one stencil kernel, the objective's and
//! the change's sums; the host receives 5 sums and the proposal `x` (the video grid),
//! which the observers read.
//!
//! Device memory: four video-grid vectors (`x`, `x_new`, `y`, the gradient), one set of
//! padded planes and one of half spectra per frame, four sensor-sized vectors.

use super::{cfg, ck, objective, DeviceCapture, Gpu};
use crate::model::data::DataTerm;
use crate::model::op::ShutterConvolution;
use crate::solve::optimize::admm_split::SplitParams;
use crate::solve::optimize::common::fista_momentum;
use crate::solve::optimize::executor::{run, Accepted, Objective, Step};
use crate::solve::optimize::fista::Fista;
use crate::solve::optimize::types::{Observer, SolveResult};
use crate::solve::prox::TotalVariation;
use cudarc::cufft::sys::float2;
use cudarc::driver::{CudaSlice, PushKernelArg};

/// `fista` on the CUDA device (checked by the caller: [`Gpu::get`] and
/// [`crate::solve::optimize::SolverKind::check_device_problem`]): step `1 / lipschitz`,
/// adaptive restart (the objective test) when `restart` is set.
///
/// # Panics
/// When the device is not available, or a CUDA call fails (out of device memory, a
/// lost device); the message names the call.
pub fn solve(fista: &Fista, sc: ShutterConvolution, data: &DataTerm, tv: &TotalVariation, x0: Option<Vec<f32>>, observer: &mut dyn Observer) -> SolveResult {
    let Fista { lipschitz, ref stop, restart } = *fista;
    let restart = restart.is_some();
    let gpu = Gpu::get().unwrap_or_else(|e| panic!("{e}"));
    assert!(lipschitz.is_finite() && lipschitz > 0.0, "Lipschitz constant must be positive");
    run(stop, observer, || GpuFista::new(gpu, sc, *data, tv, lipschitz, restart, x0))
}

/// Accumulator slots (f64): the data term's sum of squares, the TV sums (t, y, x, and
/// one left 0), the change `|x_new - x|^2` and `|x_new|^2`.
const ACC_DATA: usize = 0;
const ACC_TV: usize = 2;
const ACC_CHANGE: usize = 6;
const ACC_LEN: usize = 8;

struct GpuFista<'a> {
    gpu: &'static Gpu,
    tv: &'a TotalVariation,
    cap: DeviceCapture,
    step: f32,
    restart: bool,
    t: f64,
    x: CudaSlice<f32>,
    x_new: CudaSlice<f32>,
    y: CudaSlice<f32>,
    grad: CudaSlice<f32>,
    ax: CudaSlice<f32>,
    ax_new: CudaSlice<f32>,
    ay: CudaSlice<f32>,
    plane: CudaSlice<f32>,
    spec: CudaSlice<float2>,
    acc: CudaSlice<f64>,
    /// The accepted iterate and the proposal, on the host.
    host_x: Vec<f32>,
    host_new: Vec<f32>,
    rel_change: f64,
}

impl<'a> GpuFista<'a> {
    fn new(
        gpu: &'static Gpu,
        sc: ShutterConvolution,
        data: DataTerm,
        tv: &'a TotalVariation,
        lipschitz: f64,
        restart: bool,
        x0: Option<Vec<f32>>,
    ) -> (Self, Objective) {
        let st = &gpu.stream;
        // The grids and the frames each sensor row sees (admm-split's penalties unused).
        let cap = DeviceCapture::new(gpu, &sc, &data, tv, &SplitParams::default());
        let (g, f, m) = (cap.s.g, cap.f, cap.m);
        let (k, n) = (g.k, g.n);
        let grid = k * g.mv * g.nv;
        let x_host = x0.unwrap_or_else(|| vec![0.0; grid]);
        assert_eq!(x_host.len(), grid);
        let up = |v: &[f32]| ck(st.clone_htod(v), "copy to the device");
        let zeros = |len: usize| ck(st.alloc_zeros::<f32>(len), "device allocation");
        let x = up(&x_host);
        let mut step = GpuFista {
            gpu,
            tv,
            step: (1.0 / lipschitz) as f32,
            restart,
            t: 1.0,
            y: ck(st.clone_dtod(&x), "device copy"),
            x_new: zeros(grid),
            grad: zeros(grid),
            x,
            ax: zeros(m * n),
            ax_new: zeros(m * n),
            ay: zeros(m * n),
            plane: zeros(k * g.p * g.q),
            spec: ck(st.alloc_zeros::<float2>(k * f), "device allocation"),
            acc: ck(st.alloc_zeros::<f64>(ACC_LEN), "device allocation"),
            host_new: vec![0.0; grid],
            host_x: x_host,
            rel_change: 0.0,
            cap,
        };
        // A x at the start (into ax_new, then kept as ax and ay), and its objective.
        ck(st.memset_zeros(&mut step.acc), "device memset");
        step.forward_of(false);
        ck(st.memcpy_dtod(&step.ax_new, &mut step.ax), "device copy");
        ck(st.memcpy_dtod(&step.ax_new, &mut step.ay), "device copy");
        let acc = ck(st.clone_dtoh(&step.acc), "copy from the device");
        let objective = step.objective(&acc);
        (step, objective)
    }

    /// `ax_new = A v` with the data term's and the TV's sums added to `acc`, for
    /// `v = x_new` (`proposal`) or `x`.
    fn forward_of(&mut self, proposal: bool) {
        let (g, gpu) = (self.cap.s.g, self.gpu);
        let (ki, pi, qi, mvi, nvi) = (g.k as i32, g.p as i32, g.q as i32, g.mv as i32, g.nv as i32);
        let v = if proposal { &self.x_new } else { &self.x };
        {
            let mut l = gpu.stream.launch_builder(gpu.f("place"));
            l.arg(&mut self.plane).arg(v).arg(&ki).arg(&pi).arg(&qi).arg(&mvi).arg(&nvi);
            ck(unsafe { l.launch(cfg(g.k * g.p * g.q)) }, "kernel place");
        }
        self.cap.tv_sums(gpu, v, (g.mv, g.nv), &mut self.acc.slice_mut(ACC_TV..ACC_TV + 4));
        ck(self.cap.r2c.exec_r2c(&self.plane, &mut self.spec), "cuFFT forward");
        self.cap.forward_from_spectrum(gpu, &mut self.spec, &mut self.plane, &mut self.ax_new, &mut self.acc.slice_mut(ACC_DATA..ACC_DATA + 2));
    }

    fn objective(&self, acc: &[f64]) -> Objective {
        objective(self.tv, acc[ACC_DATA], &acc[ACC_TV..ACC_TV + 3])
    }
}

impl Step for GpuFista<'_> {
    /// A NaN in the proposal reaches its objective (the TV sums read every entry, the
    /// Haar kernel keeps NaN), so the iterate needs no host scan.
    const CHECK_ITERATE: bool = false;

    fn propose(&mut self, _: usize) -> Objective {
        let (g, gpu) = (self.cap.s.g, self.gpu);
        let st = &gpu.stream;
        let (ki, pi, qi, mvi, nvi) = (g.k as i32, g.p as i32, g.q as i32, g.mv as i32, g.nv as i32);
        let grid = g.k * g.mv * g.nv;
        ck(st.memset_zeros(&mut self.acc), "device memset");
        // The gradient step at y: grad = y - step A^T (A y - b).
        ck(st.memset_zeros(&mut self.plane), "device memset");
        {
            let null = 0u64;
            let mut l = st.launch_builder(gpu.f("scatter_adjoint"));
            l.arg(&mut self.plane).arg(&self.ay).arg(&self.cap.b);
            self.cap.push_lower_and_mask(&mut l, &null);
            l.arg(&self.cap.row_weights).arg(&self.cap.row_frames);
            self.cap.push_sensor_grid(&mut l);
            ck(unsafe { l.launch(cfg(self.cap.m * self.cap.s.slots * g.n)) }, "kernel scatter_adjoint");
        }
        ck(self.cap.r2c.exec_r2c(&self.plane, &mut self.spec), "cuFFT forward");
        self.cap.times_h(gpu, &mut self.spec, true);
        ck(self.cap.c2r.exec_c2r(&mut self.spec, &mut self.plane), "cuFFT inverse");
        {
            let step_s = self.step / (g.p * g.q) as f32;
            let mut l = st.launch_builder(gpu.f("descend"));
            l.arg(&mut self.grad).arg(&self.y).arg(&self.plane).arg(&ki).arg(&pi).arg(&qi).arg(&mvi).arg(&nvi).arg(&step_s);
            ck(unsafe { l.launch(cfg(grid)) }, "kernel descend");
        }
        // The Haar map (thresholds J gamma tau w_a, gamma = step), as the CPU's.
        {
            let dims = [g.k, g.mv, g.nv];
            let act: [i32; 3] = [0, 1, 2].map(|a| (self.tv.weights[a] > 0.0 && dims[a] > 1 && self.tv.tau > 0.0) as i32);
            let terms = 2 * act.iter().sum::<i32>();
            let j = terms.max(1) as f32;
            let c = [0, 1, 2].map(|a| j * self.step * self.tv.tau * self.tv.weights[a]);
            let inv = if terms == 0 { 0.0f32 } else { 1.0 / j };
            let nonneg = self.tv.nonneg as i32;
            let mut l = st.launch_builder(gpu.f("haar_prox"));
            l.arg(&mut self.x_new)
                .arg(&self.grad)
                .arg(&ki)
                .arg(&mvi)
                .arg(&nvi)
                .arg(&c[0])
                .arg(&c[1])
                .arg(&c[2])
                .arg(&act[0])
                .arg(&act[1])
                .arg(&act[2])
                .arg(&inv)
                .arg(&nonneg);
            ck(unsafe { l.launch(cfg(grid)) }, "kernel haar_prox");
        }
        // A x_new with the objective's sums; the change from x.
        self.forward_of(true);
        {
            let n = grid as i64;
            let mut acc = self.acc.slice_mut(ACC_CHANGE..ACC_CHANGE + 2);
            let mut l = st.launch_builder(gpu.f("change"));
            l.arg(&self.x_new).arg(&self.x).arg(&n).arg(&mut acc);
            ck(unsafe { l.launch(cfg(grid)) }, "kernel change");
        }
        let acc = ck(st.clone_dtoh(&self.acc), "copy from the device");
        self.rel_change = (acc[ACC_CHANGE] / acc[ACC_CHANGE + 1].max(1e-300)).sqrt();
        ck(st.memcpy_dtoh(&self.x_new, &mut self.host_new), "copy from the device");
        self.objective(&acc)
    }

    fn proposal(&self) -> &[f32] {
        &self.host_new
    }

    fn accept(&mut self, _: usize, current: Objective, proposed: Objective) -> Accepted {
        let t = self.t;
        let (t_new, beta) = fista_momentum(t, self.restart && proposed.total() > current.total());
        let gpu = self.gpu;
        let st = &gpu.stream;
        let launch = |out: &mut CudaSlice<f32>, new: &CudaSlice<f32>, old: &CudaSlice<f32>| {
            let n = new.len() as i64;
            let mut l = st.launch_builder(gpu.f("momentum"));
            l.arg(out).arg(new).arg(old).arg(&n).arg(&beta);
            ck(unsafe { l.launch(cfg(n as usize)) }, "kernel momentum");
        };
        launch(&mut self.y, &self.x_new, &self.x);
        launch(&mut self.ay, &self.ax_new, &self.ax);
        std::mem::swap(&mut self.x, &mut self.x_new);
        std::mem::swap(&mut self.ax, &mut self.ax_new);
        std::mem::swap(&mut self.host_x, &mut self.host_new);
        self.t = t_new;
        Accepted { objective: proposed, rel_change: self.rel_change }
    }

    fn x(&self) -> &[f32] {
        &self.host_x
    }

    fn into_x(self) -> Vec<f32> {
        self.host_x
    }
}
