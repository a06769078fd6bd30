//! The one byte budget. Every size that comes from outside (a file header, capture.toml,
//! a flag) is turned into bytes and checked here *before* anything of that size is
//! allocated, so a 124-byte file that announces 200000 x 200000 pixels gets an error
//! naming the file and the figure instead of an abort.
//!
//! The limit is 90% of the memory the system reports available (`MemAvailable` in
//! `/proc/meminfo`; 16 GiB where that cannot be read), or the value of the environment
//! variable `ROLLCAM_MEMORY_LIMIT_GB` (a positive number of gigabytes, 1e9 bytes) when it
//! is set. It is read once per process.

use std::sync::OnceLock;

/// The environment variable that sets the limit (gigabytes, 1e9 bytes).
pub const LIMIT_ENV: &str = "ROLLCAM_MEMORY_LIMIT_GB";

/// The limit used where the system's available memory cannot be read.
const FALLBACK_BYTES: u64 = 16 << 30;

/// Where the limit came from, for messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LimitSource {
    /// 90% of `MemAvailable`.
    Available,
    /// `ROLLCAM_MEMORY_LIMIT_GB`.
    Environment,
    /// Neither could be read: a fixed 16 GiB.
    Fallback,
}

/// How many bytes one process may ask for at once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ByteBudget {
    pub limit_bytes: u64,
    pub source: LimitSource,
}

/// A request the budget refuses: `what` needs `bytes`, more than `limit_bytes`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{what} needs {} of memory, more than the {} this process may use ({}); {}", gib(*bytes), gib(*limit_bytes), source_text(*limit_source), hint(*limit_source))]
pub struct OverBudget {
    pub what: String,
    /// Saturates at `u64::MAX` when the size itself overflows.
    pub bytes: u64,
    pub limit_bytes: u64,
    pub limit_source: LimitSource,
}

fn gib(bytes: u64) -> String {
    let g = bytes as f64 / (1u64 << 30) as f64;
    if g >= 1e6 {
        format!("{g:.3e} GiB")
    } else if g >= 0.1 {
        format!("{g:.1} GiB")
    } else {
        format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64)
    }
}

fn source_text(source: LimitSource) -> &'static str {
    match source {
        LimitSource::Available => "90% of the memory available now",
        LimitSource::Environment => "set by ROLLCAM_MEMORY_LIMIT_GB",
        LimitSource::Fallback => "available memory unknown, a fixed 16 GiB",
    }
}

fn hint(source: LimitSource) -> &'static str {
    match source {
        LimitSource::Environment => "raise ROLLCAM_MEMORY_LIMIT_GB if the machine has more",
        _ => "check the size, or set ROLLCAM_MEMORY_LIMIT_GB",
    }
}

impl ByteBudget {
    /// The process's budget (read once: the environment, else the system's memory).
    pub fn system() -> ByteBudget {
        static BUDGET: OnceLock<ByteBudget> = OnceLock::new();
        *BUDGET.get_or_init(|| Self::from_parts(std::env::var(LIMIT_ENV).ok().as_deref(), mem_available_bytes()))
    }

    /// The budget from the environment variable's value and the available bytes. An
    /// unusable variable (not a positive finite number) is ignored with a warning.
    pub fn from_parts(env: Option<&str>, available: Option<u64>) -> ByteBudget {
        if let Some(text) = env {
            match text.trim().parse::<f64>() {
                Ok(gb) if gb.is_finite() && gb > 0.0 => {
                    return ByteBudget { limit_bytes: (gb * 1e9).min(u64::MAX as f64) as u64, source: LimitSource::Environment }
                }
                _ => tracing::warn!("{LIMIT_ENV} = {text:?} ignored: expected a positive number of gigabytes"),
            }
        }
        match available {
            Some(b) => ByteBudget { limit_bytes: b / 10 * 9, source: LimitSource::Available },
            None => ByteBudget { limit_bytes: FALLBACK_BYTES, source: LimitSource::Fallback },
        }
    }

    /// Refuses `bytes` over the limit; `what` names the thing (and its file or field).
    pub fn check(&self, what: impl FnOnce() -> String, bytes: u128) -> Result<(), OverBudget> {
        if bytes <= u128::from(self.limit_bytes) {
            Ok(())
        } else {
            Err(OverBudget { what: what(), bytes: u64::try_from(bytes).unwrap_or(u64::MAX), limit_bytes: self.limit_bytes, limit_source: self.source })
        }
    }

    /// [`check`](Self::check) for an array of `dims` elements of `elem_bytes` each.
    pub fn check_array(&self, what: impl FnOnce() -> String, dims: &[usize], elem_bytes: usize) -> Result<(), OverBudget> {
        self.check(what, array_bytes(dims, elem_bytes))
    }
}

/// Refuses a reconstruction of `cfg` on `fov` (`channels` channels) whose estimated
/// memory ([`crate::solve::problem::memory_estimate`]), times the `workers` solving at
/// once, is over the process's budget, with the figure and what it is made of.
pub fn check_reconstruction(
    cfg: &crate::model::capture::CaptureConfig,
    fov: crate::model::capture::Fov,
    channels: usize,
    workers: usize,
) -> Result<(), OverBudget> {
    let est = crate::solve::problem::memory_estimate(cfg, fov, channels);
    let workers = workers.max(1);
    let what = || match workers {
        1 => format!("this reconstruction ({})", est.describe()),
        w => format!("reconstructing frames with {w} worker(s) (each: {})", est.describe()),
    };
    ByteBudget::system().check(what, u128::from(est.bytes) * workers as u128)
}

/// Refuses a reconstruction split across `ranks` MPI ranks, `ranks_here` of them on
/// this machine, whose memory on this machine is over the budget: each rank holds its
/// share of the solve's volumes (`1/ranks` of [`check_reconstruction`]'s) and the
/// model's buffers, and rank 0 also the gathered video of every channel.
pub fn check_split_reconstruction(
    cfg: &crate::model::capture::CaptureConfig,
    fov: crate::model::capture::Fov,
    channels: usize,
    ranks: usize,
    ranks_here: usize,
) -> Result<(), OverBudget> {
    let est = crate::solve::problem::memory_estimate(cfg, fov, channels);
    let ranks = ranks.max(1) as u128;
    let volumes = u128::from(est.volume_bytes) * u128::from(crate::solve::problem::VOLUMES_PER_CHANNEL) * channels as u128;
    let per_rank = volumes.div_ceil(ranks) + u128::from(est.weights_bytes) + u128::from(est.model_bytes);
    let gathered = u128::from(est.volume_bytes) * channels as u128;
    let bytes = per_rank * ranks_here.max(1) as u128 + gathered;
    ByteBudget::system().check(
        || format!("this reconstruction split across {ranks} MPI ranks, {ranks_here} on this machine (the whole: {}; each rank its share of the volumes, rank 0 the gathered video)", est.describe()),
        bytes,
    )
}

/// Refuses a simulation of `captures` captures of `cfg` whose memory is over the budget:
/// the truth videos (each held `copies` times, e.g. 2 while its TIFF copy is written),
/// one raw per capture, and the simulator's buffers at raw resolution (the PSF and its
/// padded spectrum, [`SIMULATOR_BYTES_PER_PIXEL`] of accumulators). Checked before the
/// PSF is synthesised, so a sensor of 65536 x 65536 is refused with the figure.
pub fn check_simulation(cfg: &crate::model::capture::CaptureConfig, captures: usize, copies: usize) -> Result<(), OverBudget> {
    let est = crate::solve::problem::memory_estimate(cfg, crate::model::capture::Fov::Sensor, 1);
    let truth_bytes = est.volume_bytes;
    let held = match copies {
        0 | 1 => String::new(),
        2 => ", held twice".to_string(),
        n => format!(", held {n} times"),
    };
    let pixels = cfg.rows as u128 * cfg.cols as u128;
    let working = u128::from(est.model_bytes) + pixels * u128::from(SIMULATOR_BYTES_PER_PIXEL) + pixels * 4 * captures as u128;
    ByteBudget::system().check(
        || {
            format!(
                "simulating {captures} capture(s) of {} x {} ({:.1} MB of truth video each{held}, {:.1} MB of raws, PSF and accumulators)",
                cfg.rows,
                cfg.cols,
                truth_bytes as f64 / 1e6,
                working as f64 / 1e6
            )
        },
        u128::from(truth_bytes).saturating_mul(copies as u128).saturating_mul(captures as u128).saturating_add(working),
    )
}

/// Bytes per raw pixel the simulator holds besides the truth, the raws and the PSF's
/// spectrum: the PSF in f64, electrons, a group's and a frame's f64 accumulators and
/// two f32 planes.
pub const SIMULATOR_BYTES_PER_PIXEL: u64 = 8 * 4 + 4 * 2;

/// Refuses a consecutive simulation whose truth on the global time grid (`frames` video
/// frames of the grid of `cfg`, held twice while its TIFF copy is written) is over the
/// budget.
pub fn check_sequence_truth(cfg: &crate::model::capture::CaptureConfig, frames: usize) -> Result<(), OverBudget> {
    let (m, n) = cfg.grid();
    ByteBudget::system().check(
        || format!("the truth of these captures ({frames} video frames of {m} x {n} on their common time grid, held twice)"),
        array_bytes(&[frames, m, n, 2], 4),
    )
}

/// Bytes of an array of `dims` elements of `elem_bytes` each, saturating (never wraps).
pub fn array_bytes(dims: &[usize], elem_bytes: usize) -> u128 {
    dims.iter().fold(elem_bytes as u128, |acc, &d| acc.saturating_mul(d as u128))
}

/// Memory the system reports available (`MemAvailable`), bytes.
pub fn mem_available_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/meminfo").ok()?;
    let kb: u64 = s.lines().find(|l| l.starts_with("MemAvailable:"))?.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limit_from_environment_wins_and_bad_values_fall_back() {
        let b = ByteBudget::from_parts(Some("2.5"), Some(100 << 30));
        assert_eq!((b.limit_bytes, b.source), (2_500_000_000, LimitSource::Environment));
        for bad in ["-1", "0", "nan", "inf", "lots"] {
            let b = ByteBudget::from_parts(Some(bad), Some(1000));
            assert_eq!((b.limit_bytes, b.source), (900, LimitSource::Available), "{bad}");
        }
        assert_eq!(ByteBudget::from_parts(None, None).source, LimitSource::Fallback);
    }

    #[test]
    fn sizes_saturate_and_are_refused_with_the_figure() {
        let b = ByteBudget { limit_bytes: 1 << 30, source: LimitSource::Environment };
        assert!(b.check_array(|| "x".into(), &[16384, 16384], 4).is_ok());
        let e = b.check_array(|| "big.tiff: 200000 x 200000 pixels".into(), &[200_000, 200_000], 4).unwrap_err();
        assert_eq!(e.bytes, 160_000_000_000);
        let msg = e.to_string();
        assert!(msg.starts_with("big.tiff: 200000 x 200000 pixels needs 149.0 GiB"), "{msg}");
        assert!(msg.contains("ROLLCAM_MEMORY_LIMIT_GB"), "{msg}");
        assert_eq!(array_bytes(&[usize::MAX, usize::MAX, 4], 8), u128::MAX);
        assert!(b.check_array(|| "overflow".into(), &[usize::MAX, usize::MAX, usize::MAX], 8).is_err());
    }
}
