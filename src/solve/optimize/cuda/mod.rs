//! The CUDA device (feature `cuda`): the driver, cuFFT and NVRTC are loaded from the
//! system at run time (nothing is needed to build), the kernels of [`split`] and [`fista`] are
//! compiled once per process. [`Gpu::get`] says in words what is missing.

pub mod fista;
pub mod split;

use crate::model::data::DataTerm;
use crate::model::op::ShutterConvolution;
use crate::solve::optimize::admm_split::{SplitParams, SplitSetup};
use crate::solve::optimize::executor::Objective;
use crate::solve::prox::TotalVariation;
use cudarc::cufft::sys::{cufftType, float2};
use cudarc::cufft::CudaFft;
use cudarc::driver::{CudaContext, CudaFunction, CudaModule, CudaSlice, CudaStream, CudaViewMut, LaunchArgs, LaunchConfig, PushKernelArg};
use std::sync::{Arc, OnceLock};

/// The kernels' source (`kernels.cu`).
const KERNELS: &str = include_str!("kernels.cu");

/// Names of the kernels in [`KERNELS`].
const KERNEL_NAMES: [&str; 21] = [
    "symbols",
    "factor",
    "rhs_space",
    "scatter_resid",
    "combine_sweep",
    "mul_h",
    "scale",
    "gather_seen",
    "z_update",
    "diff_init",
    "u_update",
    "w_update",
    "tv_sums",
    "place",
    "forward_gather",
    "scatter_adjoint",
    "descend",
    "haar_prox",
    "change",
    "momentum",
    "mul_h_inplace",
];

/// One CUDA device with the kernels loaded.
pub struct Gpu {
    pub name: String,
    pub stream: Arc<CudaStream>,
    _module: Arc<CudaModule>,
    functions: Vec<(&'static str, CudaFunction)>,
}

// The driver API's handles are usable from any thread once the context is bound,
// which cudarc does on every call.
unsafe impl Send for Gpu {}
unsafe impl Sync for Gpu {}

impl Gpu {
    /// The device, started and its kernels compiled at the first call; the same error
    /// on every call when it cannot start.
    pub fn get() -> Result<&'static Gpu, String> {
        static GPU: OnceLock<Result<Gpu, String>> = OnceLock::new();
        GPU.get_or_init(Gpu::start).as_ref().map_err(Clone::clone)
    }

    fn start() -> Result<Gpu, String> {
        // cudarc panics when a library is missing; ask first so the error is a sentence.
        let missing: Vec<&str> = [
            ("libcuda (the NVIDIA driver)", unsafe { cudarc::driver::sys::is_culib_present() }),
            ("libcufft (CUDA 13 toolkit)", unsafe { cudarc::cufft::sys::is_culib_present() }),
            ("libnvrtc (CUDA 13 toolkit)", unsafe { cudarc::nvrtc::sys::is_culib_present() }),
        ]
        .into_iter()
        .filter(|(_, ok)| !ok)
        .map(|(name, _)| name)
        .collect();
        if !missing.is_empty() {
            return Err(format!("--device cuda: {} not found; install them or add their folder to LD_LIBRARY_PATH (docs/gpu.md)", missing.join(", ")));
        }
        let ctx =
            CudaContext::new(0).map_err(|e| format!("--device cuda: no CUDA device could be started ({e:?}); check nvidia-smi and CUDA_VISIBLE_DEVICES"))?;
        let name = ctx.name().unwrap_or_else(|_| "unnamed device".into());
        let ptx = cudarc::nvrtc::compile_ptx(KERNELS).map_err(|e| format!("--device cuda: NVRTC could not compile the kernels: {e:?}"))?;
        let module = ctx.load_module(ptx).map_err(|e| format!("--device cuda: the kernels could not be loaded on {name}: {e:?}"))?;
        let mut functions = Vec::new();
        for k in KERNEL_NAMES {
            functions.push((k, module.load_function(k).map_err(|e| format!("--device cuda: kernel {k}: {e:?}"))?));
        }
        Ok(Gpu { name, stream: ctx.default_stream(), _module: module, functions })
    }

    /// The kernel called `name`.
    fn f(&self, name: &str) -> &CudaFunction {
        &self.functions.iter().find(|(n, _)| *n == name).unwrap_or_else(|| panic!("no kernel {name}")).1
    }
}

/// Launch shape of a grid-stride kernel over `n` items: 256 threads a block, at most
/// 8192 blocks (the loops cover the rest).
fn cfg(n: usize) -> LaunchConfig {
    let blocks = n.div_ceil(256).clamp(1, 8192) as u32;
    LaunchConfig { grid_dim: (blocks, 1, 1), block_dim: (256, 1, 1), shared_mem_bytes: 0 }
}

/// The objective from the device's sums: the data term's sum of squares and the TV's
/// unweighted sums per axis (t, y, x).
pub(crate) fn objective(tv: &TotalVariation, data_sum_sq: f64, tv_sums: &[f64]) -> Objective {
    let tv_sum: f64 = (0..3).map(|a| tv.weights[a] as f64 * tv_sums[a]).sum();
    Objective { data_term: 0.5 * data_sum_sq, reg_term: tv.tau as f64 * tv_sum }
}

/// A CUDA call's result, or a panic naming the call.
pub(crate) fn ck<T, E: std::fmt::Debug>(r: Result<T, E>, what: &str) -> T {
    r.unwrap_or_else(|e| panic!("--device cuda: {what} failed: {e:?}"))
}

/// One capture on the device, what both steps read: the grids, the frames each sensor
/// row sees and the initial penalties ([`SplitSetup`], the CPU step's), the PSF's
/// spectrum in cuFFT's layout, batched plans over the frames, the raw, its clipped
/// pixels and the mask.
pub(crate) struct DeviceCapture {
    pub s: SplitSetup,
    /// Sensor rows, and frequencies of one frame's half spectrum (`P x (Q/2 + 1)`).
    pub m: usize,
    pub f: usize,
    pub r2c: CudaFft,
    pub c2r: CudaFft,
    pub hhat: CudaSlice<float2>,
    /// `row_frames[i * slots + s]`: the frame (-1: none); `row_weights` its weight.
    pub row_frames: CudaSlice<i32>,
    pub row_weights: CudaSlice<f32>,
    pub b: CudaSlice<f32>,
    pub lower: Option<CudaSlice<u8>>,
    pub mask: Option<CudaSlice<f32>>,
    /// The kernels' sensor-grid arguments: `M, slots, N, P, Q, off_r, off_c`.
    sensor_grid: [i32; 7],
}

impl DeviceCapture {
    /// `M, slots, N, P, Q, off_r, off_c` as seven kernel arguments (the seen entries and
    /// where the sensor sits on the padded planes).
    pub(crate) fn push_sensor_grid<'a>(&'a self, l: &mut LaunchArgs<'a>) {
        for v in &self.sensor_grid {
            l.arg(v);
        }
    }

    /// `spec *= H`, or `conj(H)` when `conj`, in place over the frames' half spectra.
    pub(crate) fn times_h(&self, gpu: &Gpu, spec: &mut CudaSlice<float2>, conj: bool) {
        let (fi, ki, ci) = (self.f as i64, self.s.g.k as i32, conj as i32);
        let mut l = gpu.stream.launch_builder(gpu.f("mul_h_inplace"));
        l.arg(spec).arg(&self.hhat).arg(&ki).arg(&fi).arg(&ci);
        ck(unsafe { l.launch(cfg(self.s.g.k * self.f)) }, "kernel mul_h_inplace");
    }

    /// `ax = A x` from `spec`, the half spectra of `x`'s padded planes (destroyed): times
    /// `H`, back to `plane`, through the shutter and the mask; the data term's sum of
    /// squares (one-sided at clipped pixels) added to `acc[0]`.
    pub(crate) fn forward_from_spectrum(
        &self,
        gpu: &Gpu,
        spec: &mut CudaSlice<float2>,
        plane: &mut CudaSlice<f32>,
        ax: &mut CudaSlice<f32>,
        acc: &mut CudaViewMut<f64>,
    ) {
        let g = self.s.g;
        self.times_h(gpu, spec, false);
        ck(self.c2r.exec_c2r(spec, plane), "cuFFT inverse");
        let scale = 1.0 / (g.p * g.q) as f32;
        let null = 0u64;
        let mut l = gpu.stream.launch_builder(gpu.f("forward_gather"));
        l.arg(ax).arg(&*plane).arg(&self.row_weights).arg(&self.row_frames).arg(&self.b);
        self.push_lower_and_mask(&mut l, &null);
        self.push_sensor_grid(&mut l);
        l.arg(&scale).arg(acc);
        ck(unsafe { l.launch(cfg(self.m * g.n)) }, "kernel forward_gather");
    }

    /// The TV's unweighted sums of `|D_t|`, `|D_y|`, `|D_x|` of the video held in `x`, laid
    /// out as `K` planes of `rows x cols` (the video grid at their top left), into
    /// `acc[0..3]`.
    pub(crate) fn tv_sums(&self, gpu: &Gpu, x: &CudaSlice<f32>, (rows, cols): (usize, usize), acc: &mut CudaViewMut<f64>) {
        let g = self.s.g;
        let (ki, ri, ci, mvi, nvi) = (g.k as i32, rows as i32, cols as i32, g.mv as i32, g.nv as i32);
        let mut l = gpu.stream.launch_builder(gpu.f("tv_sums"));
        l.arg(x).arg(&ki).arg(&ri).arg(&ci).arg(&mvi).arg(&nvi).arg(acc);
        ck(unsafe { l.launch(cfg(g.k * g.mv * g.nv)) }, "kernel tv_sums");
    }

    /// The clipped pixels and the mask as two kernel arguments, each a null pointer
    /// when the capture has none (`null` holds the 0 pushed for them).
    pub(crate) fn push_lower_and_mask<'a>(&'a self, l: &mut LaunchArgs<'a>, null: &'a u64) {
        match &self.lower {
            Some(lb) => l.arg(lb),
            None => l.arg(null),
        };
        match &self.mask {
            Some(mk) => l.arg(mk),
            None => l.arg(null),
        };
    }

    /// `p`: admm-split's penalties (the FISTA step ignores them).
    pub(crate) fn new(gpu: &Gpu, sc: &ShutterConvolution, data: &DataTerm, tv: &TotalVariation, p: &SplitParams) -> Self {
        let st = &gpu.stream;
        let (m, n) = sc.conv.sensor_shape();
        let (pp, q) = sc.conv.fft_shape();
        let k = sc.weights.frames();
        let qc = q / 2 + 1;
        let f = pp * qc;
        // H from the convolution (transposed: qc columns of length P, scaled by 1/(P Q),
        // which the kernels apply after each inverse instead), |H|^2 for the penalties.
        let unscale = (pp * q) as f32;
        let hhat_t: Vec<_> = sc.conv.spectrum().iter().map(|z| z * unscale).collect();
        let h2: Vec<f32> = hhat_t.iter().map(|z| z.norm_sqr()).collect();
        let s = SplitSetup::new(sc, tv, p, &h2);
        let mut hhat = vec![float2 { x: 0.0, y: 0.0 }; f];
        for c in 0..qc {
            for r in 0..pp {
                let z = hhat_t[c * pp + r];
                hhat[r * qc + c] = float2 { x: z.re, y: z.im };
            }
        }
        let batch = |t: cufftType| ck(CudaFft::plan_many(&[pp as i32, q as i32], None, 1, 0, None, 1, 0, t, k as i32, st.clone()), "cuFFT plan");
        let up = |v: &[f32]| ck(st.clone_htod(v), "copy to the device");
        let row_frames: Vec<i32> = s.row_frames.iter().map(|&t| if t == usize::MAX { -1 } else { t as i32 }).collect();
        let g = s.g;
        let sensor_grid = [m, s.slots, n, g.p, g.q, g.off_r, g.off_c].map(|v| v as i32);
        DeviceCapture {
            sensor_grid,
            m,
            f,
            r2c: batch(cufftType::CUFFT_R2C),
            c2r: batch(cufftType::CUFFT_C2R),
            hhat: ck(st.clone_htod(&hhat), "copy to the device"),
            row_frames: ck(st.clone_htod(&row_frames), "copy to the device"),
            row_weights: up(&s.row_weights),
            b: up(data.observations()),
            lower: data.lower_bounds().map(|l| ck(st.clone_htod(&l.iter().map(|&b| b as u8).collect::<Vec<u8>>()), "copy to the device")),
            mask: sc.mask.map(up),
            s,
        }
    }
}

/// Device bytes a step of `kind` holds for one capture (its buffers as allocated by
/// [`split`] and [`fista`], cuFFT's work areas taken as one spectrum per frame for each
/// of the two plans, TV on every axis): `(k, p, q)` frames and the padded grid,
/// `(mv, nv)` the video grid, `(m, n)` the sensor, `slots` the most frames a sensor row
/// sees.
pub fn device_bytes(split: bool, (k, p, q): (usize, usize, usize), (mv, nv): (usize, usize), (m, n): (usize, usize), slots: usize) -> u64 {
    let (k, p, q, mv, nv, m, n, slots) = (k as u64, p as u64, q as u64, mv as u64, nv as u64, m as u64, n as u64, slots as u64);
    let f = p * (q / 2 + 1);
    let (plane, spec, video, sensor, seen) = (k * p * q * 4, k * f * 8, k * mv * nv * 4, m * n * 4, m * slots * n * 4);
    // The capture: H, the row frames and weights, the raw, clipped pixels and mask.
    let capture = f * 8 + m * slots * 8 + sensor + m * n + sensor;
    let work = 2 * spec;
    let own = if split {
        // h2, lap, the pivots; z, y1, H v; v, w, y3, the planes, u and y2 on 3 axes;
        // vhat and two spectra; x and A x.
        2 * f * 4 + k * f * 4 + 3 * seen + 4 * plane + 6 * plane + 3 * spec + video + sensor
    } else {
        // x, x_new, y, the gradient; A x, A x_new, A y; the planes; one spectrum.
        4 * video + 3 * sensor + plane + spec
    };
    capture + work + own
}

/// Whether `copies` steps (admm-split's when `split`, else FISTA's) for this capture fit
/// the device's free memory (10% kept free); the error gives both figures.
pub(crate) fn check_memory(split: bool, sc: &ShutterConvolution, copies: usize) -> Result<(), String> {
    let gpu = Gpu::get()?;
    let (m, n) = sc.conv.sensor_shape();
    let k = sc.weights.frames();
    let slots = (0..m).map(|i| (0..k).filter(|&t| sc.weights.get(i, t) != 0.0).count()).max().unwrap_or(0).max(1);
    let (p, q) = sc.conv.fft_shape();
    let need = device_bytes(split, (k, p, q), sc.conv.video_shape(), (m, n), slots) * copies.max(1) as u64;
    let (free, total) = gpu.stream.context().mem_get_info().map_err(|e| format!("--device cuda: the free memory of {} could not be read: {e:?}", gpu.name))?;
    if need as f64 > 0.9 * free as f64 {
        return Err(format!(
            "--device cuda: this capture ({k} frames on a {p} x {q} padded grid, {} channel(s) at once) needs about {:.1} GB on the device, and {} has {:.1} GB free of {:.1} GB; use the CPU (--device cpu) or a smaller capture (--downsample)",
            copies.max(1),
            need as f64 / 1e9,
            gpu.name,
            free as f64 / 1e9,
            total as f64 / 1e9
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::device_bytes;

    /// The dense video (240 x 320 x 122, padded 480 x 640, a dual shutter's 4
    /// frames per row): admm-split about 2.4 GB, FISTA about 0.75 GB (docs/gpu.md); both
    /// grow by the same bytes with each frame.
    #[test]
    fn device_memory_is_counted_per_buffer_and_grows_per_frame() {
        let at = |split, k| device_bytes(split, (k, 480, 640), (240, 320), (240, 320), 4);
        let (split, fista) = (at(true, 122) as f64 / 1e9, at(false, 122) as f64 / 1e9);
        assert!((2.2..2.6).contains(&split) && (0.7..0.8).contains(&fista), "{split} {fista}");
        for s in [true, false] {
            assert_eq!(at(s, 3) - at(s, 2), at(s, 2) - at(s, 1), "linear in the frames");
            assert!(at(s, 2) > at(s, 1));
        }
        // Per frame, admm-split holds 10 padded planes, 5 spectra (cuFFT's work areas
        // counted), its pivots and 1 video frame; FISTA 1 plane, 3 spectra, 4 video frames.
        let (p, spec) = (480 * 640 * 4u64, 480 * 321 * 8u64);
        assert_eq!(at(true, 2) - at(true, 1) - (at(false, 2) - at(false, 1)), 9 * p + 2 * spec + 480 * 321 * 4 - 3 * 240 * 320 * 4);
    }
}
