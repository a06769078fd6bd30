//! Where a solver runs: the CPU (every solver) or an NVIDIA GPU through CUDA (admm-split,
//! in builds with the `cuda` feature). The one place a device is named, parsed and
//! checked; [`crate::solve::optimize::SolverKind::check_device`] decides which solver
//! runs where.

use serde::Serialize;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Device {
    #[default]
    Cpu,
    /// The first CUDA device (`CUDA_VISIBLE_DEVICES` picks another).
    Cuda,
}

impl Device {
    pub fn name(self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            Device::Cuda => "cuda",
        }
    }

    /// Whether this device can run here: a CUDA device needs a build with the `cuda`
    /// feature, the driver and CUDA 13's libcufft and libnvrtc, and a GPU. The first
    /// check starts the device and compiles its kernels (once per process); the error
    /// says what is missing.
    pub fn check(self) -> Result<(), String> {
        match self {
            Device::Cpu => Ok(()),
            #[cfg(feature = "cuda")]
            Device::Cuda => crate::solve::optimize::cuda::Gpu::get().map(|_| ()),
            #[cfg(not(feature = "cuda"))]
            Device::Cuda => {
                Err("--device cuda: this rollcam was built without CUDA; build it with `cargo build --release --features cuda` (docs/gpu.md)".into())
            }
        }
    }

    /// The device's name as the reports print it (`cuda (NVIDIA H100 80GB HBM3)`).
    pub fn describe(self) -> String {
        match self {
            Device::Cpu => "cpu".into(),
            #[cfg(feature = "cuda")]
            Device::Cuda => match crate::solve::optimize::cuda::Gpu::get() {
                Ok(g) => format!("cuda ({})", g.name),
                Err(_) => "cuda (unavailable)".into(),
            },
            #[cfg(not(feature = "cuda"))]
            Device::Cuda => "cuda (not built)".into(),
        }
    }
}

impl std::fmt::Display for Device {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Device {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "cpu" => Ok(Device::Cpu),
            "cuda" | "gpu" => Ok(Device::Cuda),
            other => Err(format!("unknown device '{other}': expected cpu or cuda")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_parse_by_name_and_refuse_others() {
        assert_eq!("cpu".parse::<Device>(), Ok(Device::Cpu));
        assert_eq!("cuda".parse::<Device>(), Ok(Device::Cuda));
        assert_eq!("gpu".parse::<Device>(), Ok(Device::Cuda));
        assert!("tpu".parse::<Device>().unwrap_err().contains("expected cpu or cuda"));
        assert_eq!(Device::Cpu.check(), Ok(()));
    }

    #[cfg(not(feature = "cuda"))]
    #[test]
    fn a_build_without_cuda_says_how_to_get_it() {
        let e = Device::Cuda.check().unwrap_err();
        assert!(e.contains("--features cuda"), "{e}");
    }
}
