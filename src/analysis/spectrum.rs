//! Temporal power spectra of time courses, with the frequency axis in Hz.
//!
//! A time course (one value per frame, frame time `T_f`) is detrended (its least-squares
//! line removed), multiplied by a Hann window and zero-padded 8 times before the FFT, so
//! the peak is located finer than the native bin `1 / (K T_f)`. The power is
//! `|X(f)|^2`, one-sided, from 0 to Nyquist.

use rustfft::{num_complex::Complex, FftPlanner};
use serde::Serialize;

/// Zero-padding factor of the FFT.
pub const PAD: usize = 8;

/// A one-sided power spectrum.
#[derive(Clone, Debug, Serialize)]
pub struct Spectrum {
    pub frequency_hz: Vec<f64>,
    pub power: Vec<f64>,
    /// Native frequency resolution `1 / (K T_f)`, Hz.
    pub bin_hz: f64,
}

/// Remove the least-squares line from `x` (f64).
pub fn detrend(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let nf = n as f64;
    let tm = (nf - 1.0) / 2.0;
    let xm = x.iter().sum::<f64>() / nf;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, v) in x.iter().enumerate() {
        let t = i as f64 - tm;
        sxy += t * (v - xm);
        sxx += t * t;
    }
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    x.iter().enumerate().map(|(i, v)| v - xm - slope * (i as f64 - tm)).collect()
}

/// Power spectrum of a time course sampled every `frame_time_us`.
pub fn power_spectrum(x: &[f64], frame_time_us: f64) -> Spectrum {
    let k = x.len();
    let nfft = (k * PAD).max(2);
    let d = detrend(x);
    let mut buf: Vec<Complex<f64>> = vec![Complex::new(0.0, 0.0); nfft];
    for (i, v) in d.iter().enumerate() {
        let w = if k > 1 { 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / (k - 1) as f64).cos() } else { 1.0 };
        buf[i] = Complex::new(v * w, 0.0);
    }
    FftPlanner::new().plan_fft_forward(nfft).process(&mut buf);
    let half = nfft / 2 + 1;
    let df = 1e6 / (nfft as f64 * frame_time_us);
    Spectrum {
        frequency_hz: (0..half).map(|j| j as f64 * df).collect(),
        power: buf[..half].iter().map(|c| c.norm_sqr()).collect(),
        bin_hz: 1e6 / (k.max(1) as f64 * frame_time_us),
    }
}

impl Spectrum {
    /// Sum of spectra on the same axis.
    pub fn sum<'a>(spectra: impl IntoIterator<Item = &'a Spectrum>) -> Option<Spectrum> {
        let mut it = spectra.into_iter();
        let mut acc = it.next()?.clone();
        for s in it {
            assert_eq!(s.power.len(), acc.power.len(), "spectra on different axes");
            for (a, b) in acc.power.iter_mut().zip(&s.power) {
                *a += b;
            }
        }
        Some(acc)
    }

    /// Frequency of the highest power at or above `min_hz` (Hz), and that power.
    pub fn peak_above(&self, min_hz: f64) -> Option<(f64, f64)> {
        self.frequency_hz.iter().zip(&self.power).filter(|(f, _)| **f >= min_hz).max_by(|a, b| a.1.total_cmp(b.1)).map(|(f, p)| (*f, *p))
    }

    /// The peak, skipping the low-frequency lobe left by the window (1.5 native bins).
    pub fn peak(&self) -> Option<(f64, f64)> {
        self.peak_above(1.5 * self.bin_hz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sine_peak_in_hz() {
        // 500 Hz sampled every 220 us for 100 frames: bin = 45.45 Hz.
        let tf = 220.0;
        let x: Vec<f64> = (0..100).map(|i| 3.0 + (2.0 * std::f64::consts::PI * 500.0 * i as f64 * tf * 1e-6).sin()).collect();
        let s = power_spectrum(&x, tf);
        assert!((s.bin_hz - 1e6 / 22_000.0).abs() < 1e-9);
        assert!((s.frequency_hz.last().unwrap() - 0.5e6 / tf).abs() < 1e-6);
        let (f, _) = s.peak().unwrap();
        assert!((f - 500.0).abs() < s.bin_hz / 4.0, "{f}");
    }

    #[test]
    fn trend_is_not_a_peak() {
        let tf = 100.0;
        let x: Vec<f64> = (0..64).map(|i| i as f64 * 10.0 + (2.0 * std::f64::consts::PI * 1000.0 * i as f64 * tf * 1e-6).sin()).collect();
        let (f, _) = power_spectrum(&x, tf).peak().unwrap();
        assert!((f - 1000.0).abs() < 1e6 / (64.0 * tf), "{f}");
    }
}
