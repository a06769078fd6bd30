//! The CUDA device (feature `cuda`): the driver, cuFFT and NVRTC are loaded from the
//! system at run time (nothing is needed to build), the kernels of [`split`] and [`fista`] are
//! compiled once per process. [`Gpu::get`] says in words what is missing.

pub mod fista;
pub mod split;

use cudarc::driver::{CudaContext, CudaFunction, CudaModule, CudaStream, LaunchConfig};
use std::sync::{Arc, OnceLock};

/// The kernels' source (`kernels.cu`).
const KERNELS: &str = include_str!("kernels.cu");

/// Names of the kernels in [`KERNELS`].
const KERNEL_NAMES: [&str; 22] = [
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
    "data_value",
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
