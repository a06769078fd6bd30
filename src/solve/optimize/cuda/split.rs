//! admm-split on a CUDA device: the CPU step's arithmetic ([`crate::solve::optimize::admm_split`],
//! whose module docs state the splitting) with every plane, spectrum and split on the
//! device. Per iteration: five batched cuFFT transforms of the `K` padded planes (the
//! right-hand side and the data residual forward, `v` and `H v` back, and `H w` for the
//! objective) and eleven element-wise or per-frequency kernels (`kernels.cu`); the host
//! receives 16 sums and the iterate `x` (the video grid) each iteration, which the
//! observers read.
//!
//! The setup (grids, the frames each sensor row sees, the initial penalties, the
//! balancing rule) is the CPU step's ([`SplitSetup`]), so both run the same iterations
//! up to f32 rounding and the order of the sums.
//!
//! Device memory: `6 + 2 x (active TV axes)` real planes and three complex half
//! spectra per frame, plus `3 x (frames a row sees)` sensor-sized planes.

use super::{cfg, ck, objective, DeviceCapture, Gpu};
use crate::model::data::DataTerm;
use crate::model::op::ShutterConvolution;
use crate::solve::optimize::admm_split::SplitParams;
use crate::solve::optimize::executor::{run, Accepted, Objective, Step};
use crate::solve::optimize::types::{Observer, SolveResult, StopRule};
use crate::solve::prox::TotalVariation;
use cudarc::cufft::sys::float2;
use cudarc::driver::{CudaSlice, PushKernelArg};

/// Run admm-split on the CUDA device (checked by the caller: [`Gpu::get`]).
///
/// # Panics
/// When the device is not available, or a CUDA call fails (out of device memory, a
/// lost device); the message names the call.
pub fn solve(
    stop: &StopRule,
    params: &SplitParams,
    sc: ShutterConvolution,
    data: &DataTerm,
    tv: &TotalVariation,
    x0: Option<Vec<f32>>,
    observer: &mut dyn Observer,
) -> SolveResult {
    let gpu = Gpu::get().unwrap_or_else(|e| panic!("{e}"));
    run(stop, observer, || GpuSplit::new(gpu, sc, *data, tv, params, x0))
}

/// Accumulator slots (f64) the kernels add to.
const ACC_Z: usize = 0;
const ACC_U: usize = 2;
const ACC_W: usize = 4; // and the change of x at 6, 7
const ACC_DATA: usize = 8;
const ACC_TV: usize = 10;
const ACC_LEN: usize = 14;

struct GpuSplit<'a> {
    gpu: &'static Gpu,
    tv: &'a TotalVariation,
    p: &'a SplitParams,
    cap: DeviceCapture,
    mu: [f32; 3],
    factored: [f32; 3],
    h2: CudaSlice<f32>,
    lap: CudaSlice<f32>,
    piv: CudaSlice<f32>,
    z: CudaSlice<f32>,
    y1: CudaSlice<f32>,
    hv: CudaSlice<f32>,
    v: CudaSlice<f32>,
    w: CudaSlice<f32>,
    y3: CudaSlice<f32>,
    plane: CudaSlice<f32>,
    u: Vec<CudaSlice<f32>>,
    y2: Vec<CudaSlice<f32>>,
    vhat: CudaSlice<float2>,
    s1: CudaSlice<float2>,
    s2: CudaSlice<float2>,
    xd: CudaSlice<f32>,
    /// `A x` (the objective's; kept only for its sums).
    ax: CudaSlice<f32>,
    acc: CudaSlice<f64>,
    x: Vec<f32>,
    x_old: Vec<f32>,
    residuals: [[f64; 2]; 3],
    rel_change: f64,
}

impl<'a> GpuSplit<'a> {
    fn new(gpu: &'static Gpu, sc: ShutterConvolution, data: DataTerm, tv: &'a TotalVariation, p: &'a SplitParams, x0: Option<Vec<f32>>) -> (Self, Objective) {
        let st = &gpu.stream;
        let cap = DeviceCapture::new(gpu, &sc, &data, tv, p);
        let (g, f, m) = (cap.s.g, cap.f, cap.m);
        let k = g.k;
        let x = x0.unwrap_or_else(|| vec![0.0; k * g.mv * g.nv]);
        let v_host = cap.s.place(&x);
        let (pq, seen) = (g.p * g.q, m * cap.s.slots * g.n);
        let up_f32 = |v: &[f32]| ck(st.clone_htod(v), "copy to the device");
        let zeros_f32 = |len: usize| ck(st.alloc_zeros::<f32>(len), "device allocation");
        let zeros_c = |len: usize| ck(st.alloc_zeros::<float2>(len), "device allocation");
        let v = up_f32(&v_host);
        let mut step = GpuSplit {
            gpu,
            tv,
            p,
            mu: cap.s.mu,
            factored: [f32::NAN; 3],
            h2: zeros_f32(f),
            lap: zeros_f32(f),
            piv: zeros_f32(k * f),
            z: zeros_f32(seen),
            y1: zeros_f32(seen),
            hv: zeros_f32(seen),
            w: ck(st.clone_dtod(&v), "device copy"),
            v,
            y3: zeros_f32(k * pq),
            plane: zeros_f32(k * pq),
            u: cap.s.axes.iter().map(|_| zeros_f32(k * pq)).collect(),
            y2: cap.s.axes.iter().map(|_| zeros_f32(k * pq)).collect(),
            vhat: zeros_c(k * f),
            s1: zeros_c(k * f),
            s2: zeros_c(k * f),
            xd: up_f32(&x),
            ax: zeros_f32(m * g.n),
            acc: ck(st.alloc_zeros::<f64>(ACC_LEN), "device allocation"),
            x_old: x.clone(),
            x,
            residuals: [[0.0; 2]; 3],
            rel_change: 0.0,
            cap,
        };
        step.start();
        let objective = step.objective();
        (step, objective)
    }

    /// `|H|^2`, the Laplacian's symbol, and the splits at the start point: `u = D v`,
    /// `vhat = FFT v`, `z = H v` on the seen entries (duals zero).
    fn start(&mut self) {
        let (g, gpu) = (self.cap.s.g, self.gpu);
        let (pi, qi, qci, ki) = (g.p as i32, g.q as i32, (g.q / 2 + 1) as i32, g.k as i32);
        let [_, wy, wx] = self.cap.s.tvw;
        let (wy2, wx2) = ((wy as f64).powi(2), (wx as f64).powi(2));
        let mut l = gpu.stream.launch_builder(gpu.f("symbols"));
        l.arg(&self.cap.hhat).arg(&mut self.h2).arg(&mut self.lap).arg(&pi).arg(&qi).arg(&qci).arg(&wy2).arg(&wx2);
        ck(unsafe { l.launch(cfg(self.cap.f)) }, "kernel symbols");
        for (ai, (&a, &wa)) in self.cap.s.axes.iter().zip(&self.cap.s.wts).enumerate() {
            let ax = a as i32;
            let mut l = gpu.stream.launch_builder(gpu.f("diff_init"));
            l.arg(&mut self.u[ai]).arg(&self.v).arg(&ax).arg(&wa).arg(&ki).arg(&pi).arg(&qi);
            ck(unsafe { l.launch(cfg(g.k * g.p * g.q)) }, "kernel diff_init");
        }
        ck(self.cap.r2c.exec_r2c(&self.v, &mut self.vhat), "cuFFT forward");
        self.seen_h_v();
        ck(gpu.stream.memcpy_dtod(&self.hv, &mut self.z), "device copy");
    }

    /// `hv = H v` on the seen entries, from `vhat` (`s1` and `plane` are overwritten).
    fn seen_h_v(&mut self) {
        let (g, gpu) = (self.cap.s.g, self.gpu);
        let (fi, ki) = (self.cap.f as i64, g.k as i32);
        let mut l = gpu.stream.launch_builder(gpu.f("mul_h"));
        l.arg(&mut self.s1).arg(&self.vhat).arg(&self.cap.hhat).arg(&ki).arg(&fi);
        ck(unsafe { l.launch(cfg(g.k * self.cap.f)) }, "kernel mul_h");
        ck(self.cap.c2r.exec_c2r(&mut self.s1, &mut self.plane), "cuFFT inverse");
        let scale = 1.0 / (g.p * g.q) as f32;
        let mut l = gpu.stream.launch_builder(gpu.f("gather_seen"));
        l.arg(&mut self.hv).arg(&self.plane).arg(&self.cap.row_frames);
        self.cap.push_sensor_grid(&mut l);
        l.arg(&scale);
        ck(unsafe { l.launch(cfg(self.cap.m * self.cap.s.slots * g.n)) }, "kernel gather_seen");
    }

    /// The objective at `x = w`: the data term from `H w` through the shutter and the
    /// mask, the TV from the differences of `w` on the video grid. Reads the sums back.
    fn objective(&mut self) -> Objective {
        let (g, gpu) = (self.cap.s.g, self.gpu);
        ck(self.cap.r2c.exec_r2c(&self.w, &mut self.s2), "cuFFT forward");
        self.cap.forward_from_spectrum(gpu, &mut self.s2, &mut self.plane, &mut self.ax, &mut self.acc.slice_mut(ACC_DATA..ACC_DATA + 2));
        self.cap.tv_sums(gpu, &self.w, (g.p, g.q), &mut self.acc.slice_mut(ACC_TV..ACC_TV + 4));
        let acc = ck(gpu.stream.clone_dtoh(&self.acc), "copy from the device");
        self.residuals = [[acc[ACC_Z], acc[ACC_Z + 1]], [acc[ACC_U], acc[ACC_U + 1]], [acc[ACC_W], acc[ACC_W + 1]]];
        self.rel_change = (acc[ACC_W + 2] / acc[ACC_W + 3].max(1e-300)).sqrt();
        objective(self.tv, acc[ACC_DATA], &acc[ACC_TV..ACC_TV + 3])
    }

    /// Multiply a buffer by `s` on the device.
    fn scale(gpu: &Gpu, y: &mut CudaSlice<f32>, s: f32) {
        let n = y.len() as i64;
        let mut l = gpu.stream.launch_builder(gpu.f("scale"));
        l.arg(y).arg(&n).arg(&s);
        ck(unsafe { l.launch(cfg(n as usize)) }, "kernel scale");
    }
}

impl Step for GpuSplit<'_> {
    /// A NaN anywhere in `w` reaches the objective (the TV sums read every entry of the
    /// grid; `w_update` keeps NaN), so the iterate needs no host scan.
    const CHECK_ITERATE: bool = false;

    fn propose(&mut self, _: usize) -> Objective {
        let (g, gpu) = (self.cap.s.g, self.gpu);
        let st = &gpu.stream;
        let (ki, pi, qi, mvi, nvi) = (g.k as i32, g.p as i32, g.q as i32, g.mv as i32, g.nv as i32);
        let (fi, pq) = (self.cap.f as i64, g.p * g.q);
        let [mu1, mu2, mu3] = self.mu;
        let e = mu2 * self.cap.s.tvw[0] * self.cap.s.tvw[0];
        if self.mu != self.factored {
            let mut l = st.launch_builder(gpu.f("factor"));
            l.arg(&self.h2).arg(&self.lap).arg(&mut self.piv).arg(&ki).arg(&fi).arg(&mu1).arg(&mu2).arg(&mu3).arg(&e);
            ck(unsafe { l.launch(cfg(self.cap.f)) }, "kernel factor");
            self.factored = self.mu;
        }
        ck(st.memset_zeros(&mut self.acc), "device memset");

        // Right-hand side in space (into v), the data residual on the planes.
        {
            let mut su = [0.0f32; 3];
            let mut bufs: [(&CudaSlice<f32>, &CudaSlice<f32>); 3] = [(&self.w, &self.w); 3];
            for (ai, (&a, &wa)) in self.cap.s.axes.iter().zip(&self.cap.s.wts).enumerate() {
                su[a] = mu2 * wa;
                bufs[a] = (&self.u[ai], &self.y2[ai]);
            }
            let mut l = st.launch_builder(gpu.f("rhs_space"));
            l.arg(&mut self.v).arg(&self.w).arg(&self.y3);
            for (u, y) in &bufs {
                l.arg(*u).arg(*y);
            }
            l.arg(&su[0]).arg(&su[1]).arg(&su[2]).arg(&ki).arg(&pi).arg(&qi).arg(&mu3);
            ck(unsafe { l.launch(cfg(g.k * pq)) }, "kernel rhs_space");
        }
        let (mi, si, ni) = (self.cap.m as i32, self.cap.s.slots as i32, g.n as i32);
        ck(st.memset_zeros(&mut self.plane), "device memset");
        {
            let mut l = st.launch_builder(gpu.f("scatter_resid"));
            l.arg(&mut self.plane).arg(&self.z).arg(&self.y1).arg(&self.hv).arg(&self.cap.row_frames);
            self.cap.push_sensor_grid(&mut l);
            ck(unsafe { l.launch(cfg(self.cap.m * self.cap.s.slots * g.n)) }, "kernel scatter_resid");
        }
        ck(self.cap.r2c.exec_r2c(&self.v, &mut self.s1), "cuFFT forward");
        ck(self.cap.r2c.exec_r2c(&self.plane, &mut self.s2), "cuFFT forward");
        // Solve along time into vhat, back to space; H v on the seen entries.
        {
            let mut l = st.launch_builder(gpu.f("combine_sweep"));
            l.arg(&mut self.vhat).arg(&self.s1).arg(&self.s2).arg(&self.cap.hhat).arg(&self.h2).arg(&self.piv).arg(&ki).arg(&fi).arg(&mu1).arg(&e);
            ck(unsafe { l.launch(cfg(self.cap.f)) }, "kernel combine_sweep");
        }
        ck(st.memcpy_dtod(&self.vhat, &mut self.s1), "device copy");
        ck(self.cap.c2r.exec_c2r(&mut self.s1, &mut self.v), "cuFFT inverse");
        Self::scale(gpu, &mut self.v, 1.0 / pq as f32);
        self.seen_h_v();

        // z per sensor pixel; u per TV axis; w, and x = w on the grid.
        let null = 0u64;
        {
            let mut acc = self.acc.slice_mut(ACC_Z..ACC_Z + 2);
            let mut l = st.launch_builder(gpu.f("z_update"));
            l.arg(&mut self.z).arg(&mut self.y1).arg(&self.hv).arg(&self.cap.row_weights).arg(&self.cap.row_frames).arg(&self.cap.b);
            self.cap.push_lower_and_mask(&mut l, &null);
            l.arg(&mi).arg(&si).arg(&ni).arg(&mu1).arg(&mut acc);
            ck(unsafe { l.launch(cfg(self.cap.m * g.n)) }, "kernel z_update");
        }
        let thr = self.tv.tau / mu2;
        for (ai, (&a, &wa)) in self.cap.s.axes.iter().zip(&self.cap.s.wts).enumerate() {
            let ax = a as i32;
            let mut acc = self.acc.slice_mut(ACC_U..ACC_U + 2);
            let mut l = st.launch_builder(gpu.f("u_update"));
            l.arg(&mut self.u[ai]).arg(&mut self.y2[ai]).arg(&self.v).arg(&ax).arg(&wa).arg(&thr).arg(&ki).arg(&pi).arg(&qi).arg(&mvi).arg(&nvi).arg(&mut acc);
            ck(unsafe { l.launch(cfg(g.k * pq)) }, "kernel u_update");
        }
        {
            let nonneg = self.tv.nonneg as i32;
            let mut acc = self.acc.slice_mut(ACC_W..ACC_W + 4);
            let mut l = st.launch_builder(gpu.f("w_update"));
            l.arg(&mut self.w).arg(&mut self.y3).arg(&mut self.xd).arg(&self.v).arg(&nonneg).arg(&ki).arg(&pi).arg(&qi).arg(&mvi).arg(&nvi).arg(&mut acc);
            ck(unsafe { l.launch(cfg(g.k * pq)) }, "kernel w_update");
        }
        let objective = self.objective();
        std::mem::swap(&mut self.x, &mut self.x_old);
        ck(st.memcpy_dtoh(&self.xd, &mut self.x), "copy from the device");
        objective
    }

    fn proposal(&self) -> &[f32] {
        &self.x
    }

    fn accept(&mut self, it: usize, _: Objective, proposed: Objective) -> Accepted {
        if self.p.balance_every > 0 && it % self.p.balance_every == 0 {
            for (j, res) in self.residuals.into_iter().enumerate() {
                let Some(factor) = self.cap.s.balance(j, self.mu[j], res) else { continue };
                self.mu[j] *= factor;
                let gpu = self.gpu;
                match j {
                    0 => Self::scale(gpu, &mut self.y1, 1.0 / factor),
                    1 => self.y2.iter_mut().for_each(|y| Self::scale(gpu, y, 1.0 / factor)),
                    _ => Self::scale(gpu, &mut self.y3, 1.0 / factor),
                }
            }
        }
        Accepted { objective: proposed, rel_change: self.rel_change }
    }

    fn abandon(&mut self) {
        std::mem::swap(&mut self.x, &mut self.x_old);
    }

    fn x(&self) -> &[f32] {
        &self.x
    }

    fn into_x(self) -> Vec<f32> {
        self.x
    }
}
