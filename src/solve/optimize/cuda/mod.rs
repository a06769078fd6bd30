//! The CUDA device (feature `cuda`): the driver, cuFFT and NVRTC are loaded from the
//! system at run time (nothing is needed to build), the kernels of [`split`] and [`fista`] are
//! compiled once per process. [`Gpu::get`] says in words what is missing.

pub mod fista;
pub mod split;

use crate::model::data::DataTerm;
use crate::model::op::ShutterConvolution;
use crate::solve::optimize::admm_split::{psf_spectrum, SplitParams, SplitSetup};
use crate::solve::prox::TotalVariation;
use cudarc::cufft::sys::{cufftType, float2};
use cudarc::cufft::CudaFft;
use cudarc::driver::{CudaContext, CudaFunction, CudaModule, CudaSlice, CudaStream, LaunchArgs, LaunchConfig, PushKernelArg};
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
}

impl DeviceCapture {
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
        // H on the host (transposed: qc columns of length P), |H|^2 for the penalties.
        let hhat_t = psf_spectrum(sc.conv.psf(), (m, n), (pp, q));
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
        DeviceCapture {
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
