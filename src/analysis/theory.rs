//! What the timing alone predicts about temporal resolution.
//!
//! A row integrates the scene over its exposure `T_e`: the measurement is the scene
//! convolved in time with `rect(t / T_e)` (a box mean of width `T_e`), sampled every
//! frame time `T_f`. Hence:
//! - sampling rate `1 / T_f`, Nyquist frequency `1 / (2 T_f)`;
//! - the exposure's transfer function `|sinc(f T_e)|`, whose first zero is `1 / T_e`;
//! - a square wave of period `P` after the box mean keeps a temporal (Michelson)
//!   contrast `(max - min) / (max + min)` computed exactly by [`square_wave_contrast`];
//!   it is 1 while `T_e <= min(on, off)` and 0 when `T_e` is a whole number of periods;
//! - a global-shutter camera with the same sample budget has to spread those samples
//!   over enough frames to sample the waveform above Nyquist ([`global_shutter_equivalent`]).

use crate::sim::scene::square_wave_mean;
use serde::Serialize;

/// Sampling rate of a video with frame time `frame_time_us`, in Hz.
pub fn sampling_rate_hz(frame_time_us: f64) -> f64 {
    1e6 / frame_time_us
}

/// Nyquist frequency `1 / (2 T_f)`, in Hz.
pub fn nyquist_hz(frame_time_us: f64) -> f64 {
    0.5e6 / frame_time_us
}

/// First zero of the exposure's transfer function, `1 / T_e`, in Hz.
pub fn exposure_first_zero_hz(exposure_us: f64) -> f64 {
    1e6 / exposure_us
}

/// Amplitude transfer of a box mean of width `exposure_us` at `frequency_hz`:
/// `|sin(pi f T_e) / (pi f T_e)|`.
pub fn exposure_transfer(frequency_hz: f64, exposure_us: f64) -> f64 {
    let x = std::f64::consts::PI * frequency_hz * exposure_us * 1e-6;
    if x.abs() < 1e-12 {
        1.0
    } else {
        (x.sin() / x).abs()
    }
}

/// The extremes of a 0/1 square wave (period `period_us`, on for the first
/// `duty * period_us` of each period) after a box mean of width `window_us`.
///
/// The box mean is piecewise linear in the window's start, with kinks only where the
/// window's start or end crosses an edge of the wave, so its extremes lie on those
/// kinks: evaluating the exact mean there gives the exact max and min.
pub fn square_wave_after_box(period_us: f64, duty: f64, window_us: f64) -> (f64, f64) {
    let on = duty * period_us;
    let mut starts = vec![0.0, on];
    for e in [0.0, on, period_us, period_us + on] {
        let s = e - window_us;
        starts.push(s - (s / period_us).floor() * period_us);
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for s in starts {
        let v = square_wave_mean(s, s + window_us, period_us, duty, 0.0);
        lo = lo.min(v);
        hi = hi.max(v);
    }
    (lo, hi)
}

/// Michelson contrast `(max - min) / (max + min)` of a 0/1 square wave after a box
/// mean of width `window_us` (0 for an empty wave).
pub fn square_wave_contrast(period_us: f64, duty: f64, window_us: f64) -> f64 {
    let (lo, hi) = square_wave_after_box(period_us, duty, window_us);
    michelson(lo, hi)
}

/// `(hi - lo) / (hi + lo)`, 0 when both are 0.
pub fn michelson(lo: f64, hi: f64) -> f64 {
    if hi + lo <= 0.0 {
        0.0
    } else {
        (hi - lo) / (hi + lo)
    }
}

/// Frequencies of the harmonics of a square wave of period `period_us` and duty
/// `duty` up to `max_hz` (harmonics whose amplitude vanishes, such as the even ones at
/// duty 0.5, are left out), as (harmonic number, frequency in Hz).
pub fn square_wave_harmonics(period_us: f64, duty: f64, max_hz: f64) -> Vec<(usize, f64)> {
    let f0 = 1e6 / period_us;
    (1..)
        .map(|n| (n, n as f64 * f0))
        .take_while(|&(_, f)| f <= max_hz * (1.0 + 1e-12))
        .filter(|&(n, _)| (std::f64::consts::PI * n as f64 * duty).sin().abs() > 1e-6)
        .collect()
}

/// Where a frequency lands after sampling at `sampling_hz` (folded into `[0, fs/2]`).
pub fn alias_hz(frequency_hz: f64, sampling_hz: f64) -> f64 {
    let r = frequency_hz.rem_euclid(sampling_hz);
    r.min(sampling_hz - r)
}

/// A global-shutter camera given the same number of samples as one rolling-shutter
/// frame (`rows x cols`), asked to record the same time span at the frame rate a
/// waveform needs (Nyquist: two frames per period).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct GlobalShutterEquivalent {
    /// Samples available: rows x cols.
    pub samples: usize,
    /// Time the rolling-shutter capture spans (first row start to last row start plus
    /// one line time), microseconds.
    pub record_us: f64,
    /// Frame rate needed: 2 / period, frames per second (the camera needs more).
    pub min_frame_rate_fps: f64,
    /// Frames over the record at that rate.
    pub frames: usize,
    pub pixels_per_frame: usize,
    /// Largest frame with the sensor's aspect ratio within `pixels_per_frame`.
    pub rows: usize,
    pub cols: usize,
    /// Loss of lateral resolution: sensor rows over the global-shutter frame's rows.
    pub lateral_factor: f64,
}

/// The global-shutter equivalent of a `rows x cols` rolling-shutter capture spanning
/// `record_us` for a waveform of period `period_us` (see [`GlobalShutterEquivalent`]).
pub fn global_shutter_equivalent(rows: usize, cols: usize, record_us: f64, period_us: f64) -> GlobalShutterEquivalent {
    let samples = rows * cols;
    let frame_time_us = period_us / 2.0;
    let frames = ((record_us / frame_time_us) * (1.0 - 1e-12)).ceil().max(1.0) as usize;
    let pixels_per_frame = samples / frames;
    let aspect = rows as f64 / cols as f64;
    let mut gr = ((pixels_per_frame as f64 * aspect).sqrt().floor() as usize).max(1);
    let mut gc = ((pixels_per_frame as f64 / aspect).sqrt().floor() as usize).max(1);
    while gr * gc > pixels_per_frame && gr > 1 && gc > 1 {
        if gr as f64 / gc as f64 > aspect {
            gr -= 1;
        } else {
            gc -= 1;
        }
    }
    GlobalShutterEquivalent {
        samples,
        record_us,
        min_frame_rate_fps: 2e6 / period_us,
        frames,
        pixels_per_frame,
        rows: gr,
        cols: gc,
        lateral_factor: rows as f64 / gr as f64,
    }
}

/// Everything the timing predicts for one capture (and one waveform, when given).
#[derive(Clone, Debug, Serialize)]
pub struct Theory {
    pub frame_time_us: f64,
    pub exposure_us: f64,
    pub sampling_rate_hz: f64,
    pub nyquist_hz: f64,
    /// `1 / T_e`: first zero of the exposure's transfer function.
    pub exposure_first_zero_hz: f64,
    /// Highest usable frequency: the lower of Nyquist and `1 / T_e`.
    pub band_limit_hz: f64,
    pub waveform: Option<WaveformTheory>,
}

/// Predictions for a square wave of period `period_us`.
#[derive(Clone, Debug, Serialize)]
pub struct WaveformTheory {
    pub period_us: f64,
    pub duty: f64,
    pub frequency_hz: f64,
    /// Odd harmonics (duty 0.5) up to the sampling rate: number, frequency, where it
    /// lands after sampling, and the exposure's amplitude transfer there.
    pub harmonics: Vec<Harmonic>,
    /// Michelson contrast after the exposure's box mean (what the raw rows can carry).
    pub contrast_after_exposure: f64,
    /// Michelson contrast after the frame's box mean only (what a perfect video of
    /// frame time `T_f` would show).
    pub contrast_after_frame: f64,
    /// `|sinc(f0 T_e)|`: amplitude transfer of the fundamental into the raw rows.
    pub fundamental_transfer: f64,
    /// `|sinc(f0 T_f)|`: what averaging over one frame leaves of the fundamental (the
    /// most a video of frame time `T_f` can show).
    pub frame_fundamental_transfer: f64,
    /// Whether the fundamental lies below both Nyquist and `1 / T_e`.
    pub resolvable: bool,
    pub global_shutter: Option<GlobalShutterEquivalent>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Harmonic {
    pub n: usize,
    pub frequency_hz: f64,
    pub observed_hz: f64,
    pub transfer: f64,
}

impl Theory {
    /// `grid` (rows, cols) and `record_us` give the global-shutter comparison.
    pub fn new(frame_time_us: f64, exposure_us: f64, waveform: Option<(f64, f64)>, grid: Option<(usize, usize, f64)>) -> Theory {
        let fs = sampling_rate_hz(frame_time_us);
        let nyq = nyquist_hz(frame_time_us);
        let fz = exposure_first_zero_hz(exposure_us);
        let waveform = waveform.map(|(period_us, duty)| {
            let f0 = 1e6 / period_us;
            WaveformTheory {
                period_us,
                duty,
                frequency_hz: f0,
                harmonics: square_wave_harmonics(period_us, duty, fs)
                    .into_iter()
                    .map(|(n, f)| Harmonic { n, frequency_hz: f, observed_hz: alias_hz(f, fs), transfer: exposure_transfer(f, exposure_us) })
                    .collect(),
                contrast_after_exposure: square_wave_contrast(period_us, duty, exposure_us),
                contrast_after_frame: square_wave_contrast(period_us, duty, frame_time_us),
                fundamental_transfer: exposure_transfer(f0, exposure_us),
                frame_fundamental_transfer: exposure_transfer(f0, frame_time_us),
                resolvable: f0 < nyq.min(fz) * (1.0 - 1e-9),
                global_shutter: grid.map(|(r, c, rec)| global_shutter_equivalent(r, c, rec, period_us)),
            }
        });
        Theory { frame_time_us, exposure_us, sampling_rate_hz: fs, nyquist_hz: nyq, exposure_first_zero_hz: fz, band_limit_hz: nyq.min(fz), waveform }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: the box mean sampled densely over one period.
    fn brute(period_us: f64, duty: f64, window_us: f64) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..20_000 {
            let s = period_us * i as f64 / 20_000.0;
            let v = square_wave_mean(s, s + window_us, period_us, duty, 0.0);
            lo = lo.min(v);
            hi = hi.max(v);
        }
        (lo, hi)
    }

    #[test]
    fn exact_extremes_match_dense_sampling() {
        for &(p, d, w) in &[
            (2640.0, 0.5, 660.0),
            (1320.0, 0.5, 660.0),
            (1000.0, 0.5, 660.0),
            (900.0, 0.3, 660.0),
            (660.0, 0.5, 660.0),
            (500.0, 0.5, 660.0),
            (700.0, 0.25, 220.0),
        ] {
            let (lo, hi) = square_wave_after_box(p, d, w);
            let (blo, bhi) = brute(p, d, w);
            assert!((lo - blo).abs() < 1e-3 && (hi - bhi).abs() < 1e-3, "P={p} D={d} W={w}: exact ({lo}, {hi}) vs sampled ({blo}, {bhi})");
            // Exact never exceeds the sampled extremes' envelope.
            assert!(lo <= blo + 1e-12 && hi >= bhi - 1e-12);
        }
    }

    #[test]
    fn contrast_of_the_paper_sweep() {
        // T_e = 660 us: full contrast while T_e <= P/2, none at P = T_e.
        assert!((square_wave_contrast(2640.0, 0.5, 660.0) - 1.0).abs() < 1e-12);
        assert!((square_wave_contrast(1320.0, 0.5, 660.0) - 1.0).abs() < 1e-12);
        assert!(square_wave_contrast(660.0, 0.5, 660.0).abs() < 1e-12);
        // P = 990 us (on 495 us): a 660 us window holds at most 495 us on and at least
        // 165 us on: (0.25, 0.75) -> contrast 0.5.
        let (lo, hi) = square_wave_after_box(990.0, 0.5, 660.0);
        assert!((lo - 0.25).abs() < 1e-9 && (hi - 0.75).abs() < 1e-9, "{lo} {hi}");
        assert!((square_wave_contrast(990.0, 0.5, 660.0) - 0.5).abs() < 1e-9);
    }

    #[test]
    fn band_limits() {
        assert!((exposure_first_zero_hz(660.0) - 1515.1515).abs() < 1e-3);
        assert!((nyquist_hz(220.0) - 2272.727).abs() < 1e-2);
        assert!(exposure_transfer(1e6 / 660.0, 660.0) < 1e-12);
        assert!((exposure_transfer(0.0, 660.0) - 1.0).abs() < 1e-12);
        let h = square_wave_harmonics(2640.0, 0.5, 4545.0);
        assert_eq!(h.iter().map(|x| x.0).collect::<Vec<_>>(), vec![1, 3, 5, 7, 9, 11]);
        assert!((alias_hz(3000.0, 4545.45) - 1545.45).abs() < 1e-2);
    }

    #[test]
    fn paper_global_shutter_comparison() {
        // 270 x 320 samples, dual shutter with 135 line slots of 220 us, T = 1980 us.
        let g = global_shutter_equivalent(270, 320, 135.0 * 220.0, 1980.0);
        assert_eq!(g.samples, 86_400);
        assert_eq!(g.frames, 30);
        assert!(g.min_frame_rate_fps > 1010.0 && g.min_frame_rate_fps < 1011.0);
        assert_eq!((g.rows, g.cols), (49, 58));
        assert!(g.rows * g.cols <= g.pixels_per_frame);
    }
}
