//! The device timestamps of a capture folder (`device_timestamp_ns` of each frame's
//! sidecar) placed on the sequence's time grid (`TimeGrid::new`), as
//! `reconstruct-sequence` and `run --consecutive` do: a pause of any length, or any
//! order, is refused or placed, never a panic or an allocation past the frame bound. A
//! grid that builds holds at most `MAX_FRAMES` frames and every capture inside it.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam::model::shutter::{ShutterMode, Timing, MAX_FRAMES};
use rollcam::model::time_grid::{TimeGrid, TimeSource};

fuzz_target!(|data: &[u8]| {
    let stamps: Vec<u64> = data.chunks_exact(8).take(256).map(|c| u64::from_le_bytes(c.try_into().unwrap())).collect();
    // The reader requires timestamps after the first to be present and increasing.
    if stamps.is_empty() || !stamps.windows(2).all(|w| w[1] > w[0]) {
        return;
    }
    let weights = Timing::new(8, 10.0, 30.0, ShutterMode::Dual).weights().unwrap();
    let start_us: Vec<f64> = stamps.iter().map(|&t| (t - stamps[0]) as f64 / 1e3).collect();
    if let Ok(grid) = TimeGrid::new(&start_us, &weights, TimeSource::DeviceTimestamps) {
        assert!(grid.frames <= MAX_FRAMES, "{} frames", grid.frames);
        for c in 0..grid.captures() {
            assert!(grid.frames_of(c).end <= grid.frames);
        }
    }
});
