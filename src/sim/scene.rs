//! Time-varying scenes on the raw pixel grid.
//!
//! A scene is a radiance `L(t)` per raw pixel, in photo-electrons per microsecond
//! that the pixel would collect before the diffuser spreads them (the scene as
//! magnified onto the sensor, in sensor pixels). What the simulator needs is its time
//! integral over an interval, in photo-electrons: [`Scene::integrate`]. Scenes with
//! piecewise-constant or square-wave time dependence integrate exactly; moving scenes
//! use midpoint sub-steps ([`integrate_midpoint`]).

use super::error::{invalid, SimError};
use ndarray::{Array2, Array3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A scene of `rows x cols` raw pixels with a time-varying radiance.
pub trait Scene: Send + Sync {
    /// `(rows, cols)` of the raw pixel grid.
    fn size(&self) -> (usize, usize);
    /// Overwrite `out` (`rows x cols`, row-major) with the time integral of the
    /// radiance over `[t0_us, t1_us)`: photo-electrons per raw pixel.
    fn integrate(&self, t0_us: f64, t1_us: f64, out: &mut [f32]);
    /// Provenance for the `[scene]` table of a capture description.
    fn describe(&self) -> toml::Table;
}

/// Midpoint rule: `out = sum_j radiance(t_j) * dt` with `substeps` equal steps of
/// `dt = (t1 - t0) / substeps` and `t_j` their midpoints. `radiance(t, buf)` must
/// overwrite `buf` with the radiance (e-/us per pixel) at time `t`; `scratch` is
/// resized as needed. Exact for radiance linear in time.
pub fn integrate_midpoint(mut radiance: impl FnMut(f64, &mut [f32]), t0_us: f64, t1_us: f64, substeps: usize, out: &mut [f32], scratch: &mut Vec<f32>) {
    let n = substeps.max(1);
    let dt = (t1_us - t0_us) / n as f64;
    out.fill(0.0);
    scratch.resize(out.len(), 0.0);
    for j in 0..n {
        radiance(t0_us + (j as f64 + 0.5) * dt, scratch);
        let w = dt as f32;
        for (o, &r) in out.iter_mut().zip(scratch.iter()) {
            *o += r * w;
        }
    }
}

/// Time a square wave spends "on" during `[0, t)`, in microseconds: the wave is on
/// while `(t - phase) mod period < duty * period`. Exact, continuous in `t`.
fn square_on_time(t: f64, period_us: f64, duty: f64, phase_us: f64) -> f64 {
    let u = t - phase_us;
    let on = duty * period_us;
    let cycles = (u / period_us).floor();
    let rem = u - cycles * period_us;
    cycles * on + rem.clamp(0.0, on)
}

/// Mean on-fraction of a square wave over `[t0, t1)` (exact).
pub fn square_wave_mean(t0_us: f64, t1_us: f64, period_us: f64, duty: f64, phase_us: f64) -> f64 {
    if t1_us <= t0_us {
        return 0.0;
    }
    let on = square_on_time(t1_us, period_us, duty, phase_us) - square_on_time(t0_us, period_us, duty, phase_us);
    (on / (t1_us - t0_us)).clamp(0.0, 1.0)
}

/// Samples per pixel side of the anti-aliased disc coverage ([`disc_coverage`]).
const DISC_SAMPLES: usize = 4;

/// Anti-aliased disc coverage: for each pixel of the disc's bounding box (clipped to
/// the `rows x cols` grid) that the disc touches, `visit(index, hits)` with the
/// row-major pixel index and the number of its `DISC_SAMPLES^2` sub-pixel samples
/// inside the disc (at least 1).
fn disc_coverage(rows: usize, cols: usize, cr: f64, cc: f64, radius: f64, mut visit: impl FnMut(usize, u32)) {
    const S: usize = DISC_SAMPLES;
    let r_lo = (cr - radius).floor().max(0.0) as usize;
    let r_hi = ((cr + radius).ceil().max(0.0) as usize).min(rows);
    let c_lo = (cc - radius).floor().max(0.0) as usize;
    let c_hi = ((cc + radius).ceil().max(0.0) as usize).min(cols);
    let r2 = radius * radius;
    for i in r_lo..r_hi {
        for j in c_lo..c_hi {
            let mut hits = 0;
            for a in 0..S {
                let y = i as f64 + (a as f64 + 0.5) / S as f64 - cr;
                for b in 0..S {
                    let x = j as f64 + (b as f64 + 0.5) / S as f64 - cc;
                    if y * y + x * x <= r2 {
                        hits += 1;
                    }
                }
            }
            if hits > 0 {
                visit(i * cols + j, hits);
            }
        }
    }
}

/// Anti-aliased disc coverage: fraction of each pixel inside a disc (4 x 4 samples per
/// pixel), added as `weight * coverage` into `out` over the disc's bounding box.
fn add_disc(out: &mut [f32], rows: usize, cols: usize, cr: f64, cc: f64, radius: f64, weight: f32) {
    disc_coverage(rows, cols, cr, cc, radius, |k, hits| out[k] += weight * hits as f32 / (DISC_SAMPLES * DISC_SAMPLES) as f32);
}

/// A line of LEDs flashing square waves (the paper's resolution target).
///
/// LED `k` of `n` sits on the centre row at column `centre + (k - (n-1)/2) * spacing_px`
/// (continuous coordinates, pixel `(i, j)` covering `[i, i+1) x [j, j+1)`, centre at
/// `(rows/2, cols/2)`), as an anti-aliased disc of `radius_px` that emits `e_per_us`
/// photo-electrons per microsecond in total (summed over its pixels) while on. Its
/// square wave is on while `(t - phase_us[k]) mod period_us[k] < duty * period_us[k]`.
/// The on-time over an interval is computed exactly.
#[derive(Clone, Debug)]
pub struct LedArray {
    rows: usize,
    cols: usize,
    spacing_px: f64,
    radius_px: f64,
    period_us: Vec<f64>,
    duty: f64,
    phase_us: Vec<f64>,
    e_per_us: f64,
    /// Unit-sum spatial profile of each LED: (pixel index, weight).
    spots: Vec<Vec<(usize, f32)>>,
}

/// The LEDs of a [`LedArray`]: how many, how far apart and how large, their square
/// waves and their brightness. `period_us` and `phase_us` hold one value for all LEDs or
/// one per LED.
#[derive(Clone, Debug, PartialEq)]
pub struct LedLine {
    pub leds: usize,
    pub spacing_px: f64,
    pub radius_px: f64,
    pub period_us: Vec<f64>,
    pub duty: f64,
    pub phase_us: Vec<f64>,
    pub e_per_us: f64,
}

impl LedArray {
    /// The LEDs of `line` on a `rows x cols` scene.
    pub fn new(rows: usize, cols: usize, line: LedLine) -> Result<LedArray, SimError> {
        let LedLine { leds: n, spacing_px, radius_px, period_us, duty, phase_us, e_per_us } = line;
        if n == 0 {
            return Err(invalid("leds", 0, "at least 1 LED"));
        }
        let per_led = |name: &'static str, v: &[f64]| -> Result<Vec<f64>, SimError> {
            match v.len() {
                1 => Ok(vec![v[0]; n]),
                l if l == n => Ok(v.to_vec()),
                l => Err(invalid(name, format!("{l} values"), format!("1 value or one per LED ({n})"))),
            }
        };
        let period_us = per_led("period_us", &period_us)?;
        let phase_us = per_led("phase_us", &phase_us)?;
        if let Some(p) = period_us.iter().find(|p| !(p.is_finite() && **p > 0.0)) {
            return Err(invalid("period_us", p, "positive, finite periods in microseconds"));
        }
        if let Some(p) = phase_us.iter().find(|p| !p.is_finite()) {
            return Err(invalid("phase_us", p, "finite phases in microseconds"));
        }
        if !(duty.is_finite() && (0.0..=1.0).contains(&duty)) {
            return Err(invalid("duty", duty, "a fraction in [0, 1]"));
        }
        if !(radius_px.is_finite() && radius_px > 0.0) {
            return Err(invalid("radius_px", radius_px, "a positive radius in pixels"));
        }
        if !(spacing_px.is_finite() && spacing_px >= 0.0) {
            return Err(invalid("spacing_px", spacing_px, "a non-negative spacing in pixels"));
        }
        if !(e_per_us.is_finite() && e_per_us >= 0.0) {
            return Err(invalid("e_per_us", e_per_us, "a non-negative brightness in photo-electrons per microsecond"));
        }
        let (cr, cc0) = ((rows / 2) as f64 + 0.5, (cols / 2) as f64 + 0.5);
        let mut spots = Vec::with_capacity(n);
        let mut buf = vec![0.0f32; rows * cols];
        for k in 0..n {
            let cc = cc0 + (k as f64 - (n as f64 - 1.0) / 2.0) * spacing_px;
            buf.fill(0.0);
            add_disc(&mut buf, rows, cols, cr, cc, radius_px, 1.0);
            let total: f64 = buf.iter().map(|&v| v as f64).sum();
            if total.is_nan() || total <= 0.0 {
                return Err(invalid("spacing_px", spacing_px, format!("LEDs inside the {rows} x {cols} scene (LED {k} centred at column {cc:.1})")));
            }
            spots.push(buf.iter().enumerate().filter(|(_, &v)| v > 0.0).map(|(i, &v)| (i, (v as f64 / total) as f32)).collect());
        }
        Ok(LedArray { rows, cols, spacing_px, radius_px, period_us, duty, phase_us, e_per_us, spots })
    }

    /// The paper's target: 4 LEDs 6 px apart, radius 1.5 px, flashing in unison with
    /// one period, duty 0.5, 1000 e-/us each.
    pub fn paper(rows: usize, cols: usize, period_us: f64) -> Result<LedArray, SimError> {
        LedArray::new(
            rows,
            cols,
            LedLine { leds: 4, spacing_px: 6.0, radius_px: 1.5, period_us: vec![period_us], duty: 0.5, phase_us: vec![0.0], e_per_us: 1000.0 },
        )
    }

    pub fn leds(&self) -> usize {
        self.spots.len()
    }

    /// Mean on-fraction of LED `led` over `[t0_us, t1_us)` (exact), for comparison
    /// with a reconstructed waveform.
    pub fn waveform(&self, led: usize, t0_us: f64, t1_us: f64) -> f64 {
        square_wave_mean(t0_us, t1_us, self.period_us[led], self.duty, self.phase_us[led])
    }

    /// Centre of LED `led`, (row, col) in continuous raw pixel coordinates.
    pub fn centre_px(&self, led: usize) -> (f64, f64) {
        let n = self.spots.len() as f64;
        ((self.rows / 2) as f64 + 0.5, (self.cols / 2) as f64 + 0.5 + (led as f64 - (n - 1.0) / 2.0) * self.spacing_px)
    }

    /// Square-wave period of LED `led`, microseconds.
    pub fn period_us(&self, led: usize) -> f64 {
        self.period_us[led]
    }

    /// Raw pixels lit by LED `led`, with the unit-sum weights of its spot.
    pub fn spot(&self, led: usize) -> &[(usize, f32)] {
        &self.spots[led]
    }
}

impl Scene for LedArray {
    fn size(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }

    fn integrate(&self, t0_us: f64, t1_us: f64, out: &mut [f32]) {
        out.fill(0.0);
        for (k, spot) in self.spots.iter().enumerate() {
            let on_us = self.waveform(k, t0_us, t1_us) * (t1_us - t0_us).max(0.0);
            let e = (self.e_per_us * on_us) as f32;
            for &(i, w) in spot {
                out[i] += e * w;
            }
        }
    }

    fn describe(&self) -> toml::Table {
        let mut t = toml::Table::new();
        t.insert("kind".into(), "led-array".into());
        t.insert("leds".into(), (self.spots.len() as i64).into());
        t.insert("spacing_px".into(), self.spacing_px.into());
        t.insert("radius_px".into(), self.radius_px.into());
        t.insert("period_us".into(), self.period_us.clone().into());
        t.insert("duty".into(), self.duty.into());
        t.insert("phase_us".into(), self.phase_us.clone().into());
        t.insert("e_per_us".into(), self.e_per_us.into());
        t
    }
}

/// A bright disc moving at constant velocity over an optional static background.
///
/// At time `t` the disc of `radius_px` is centred at `start + velocity * t` (pixels,
/// continuous coordinates), reflected off the field's edges: it bounces, staying whole
/// inside the field, so a scene of any length has it in every frame. Pixels it covers
/// (anti-aliased) have radiance `disc_e_per_us`, the others `background_e_per_us`
/// (e-/us per pixel; the disc occludes the background). Integrated by `substeps`
/// midpoint steps per call; the background part is exact.
#[derive(Clone, Debug)]
pub struct MovingDisc {
    pub rows: usize,
    pub cols: usize,
    pub radius_px: f64,
    /// Centre at t = 0, (row, col) in pixels.
    pub start_px: (f64, f64),
    /// (rows, cols) per microsecond.
    pub velocity_px_per_us: (f64, f64),
    pub disc_e_per_us: f64,
    pub background_e_per_us: f64,
    /// Midpoint sub-steps per [`Scene::integrate`] call.
    pub substeps: usize,
}

impl MovingDisc {
    /// A disc of `radius_px` crossing the scene, 8 sub-steps per call, no background.
    pub fn new(rows: usize, cols: usize, radius_px: f64, start_px: (f64, f64), velocity_px_per_us: (f64, f64), disc_e_per_us: f64) -> MovingDisc {
        MovingDisc { rows, cols, radius_px, start_px, velocity_px_per_us, disc_e_per_us, background_e_per_us: 0.0, substeps: 8 }
    }

    /// Centre (row, col) in pixels at time `t_us`: the straight path folded back into
    /// `[radius, side - radius]` on each axis (a bounce off each edge).
    pub fn centre_px(&self, t_us: f64) -> (f64, f64) {
        let r = self.radius_px;
        (
            bounce(self.start_px.0 + self.velocity_px_per_us.0 * t_us, r, self.rows as f64 - r),
            bounce(self.start_px.1 + self.velocity_px_per_us.1 * t_us, r, self.cols as f64 - r),
        )
    }
}

/// `x` folded into `[lo, hi]` by reflection off both ends (the middle when the range
/// is empty).
fn bounce(x: f64, lo: f64, hi: f64) -> f64 {
    let span = hi - lo;
    if span.is_nan() || span <= 0.0 {
        return 0.5 * (lo + hi);
    }
    let u = (x - lo).rem_euclid(2.0 * span);
    lo + if u <= span { u } else { 2.0 * span - u }
}

impl Scene for MovingDisc {
    fn size(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }

    fn integrate(&self, t0_us: f64, t1_us: f64, out: &mut [f32]) {
        let span = (t1_us - t0_us).max(0.0);
        out.fill((self.background_e_per_us * span) as f32);
        let n = self.substeps.max(1);
        let dt = span / n as f64;
        let w = ((self.disc_e_per_us - self.background_e_per_us) * dt) as f32;
        for j in 0..n {
            let (cr, cc) = self.centre_px(t0_us + (j as f64 + 0.5) * dt);
            add_disc(out, self.rows, self.cols, cr, cc, self.radius_px, w);
        }
    }

    fn describe(&self) -> toml::Table {
        let mut t = toml::Table::new();
        t.insert("kind".into(), "moving-disc".into());
        t.insert("radius_px".into(), self.radius_px.into());
        t.insert("start_px".into(), vec![self.start_px.0, self.start_px.1].into());
        t.insert("velocity_px_per_us".into(), vec![self.velocity_px_per_us.0, self.velocity_px_per_us.1].into());
        t.insert("disc_e_per_us".into(), self.disc_e_per_us.into());
        t.insert("background_e_per_us".into(), self.background_e_per_us.into());
        t.insert("substeps".into(), (self.substeps as i64).into());
        t
    }
}

/// A bright disc moving at constant velocity over a static textured image, both part
/// of the scene (the dense benchmark scene: the truth is the whole scene, texture
/// included, unlike the bench's [`super::sensor::BackgroundTexture`] behind a scene).
///
/// The texture is a radiance image (`rows x cols`, e-/us per pixel). At time `t` the
/// disc of `radius_px` is centred at `start + velocity * t` (pixels, continuous
/// coordinates: pixel `(i, j)` covers `[i, i+1) x [j, j+1)`); the fraction of a pixel
/// it covers (anti-aliased, 4 x 4 samples per pixel as for [`MovingDisc`]) has the
/// disc's radiance `disc_e_per_us`, the rest the texture's: the disc occludes the
/// texture. [`Scene::integrate`] is exact for the texture and integrates the disc by
/// `substeps` midpoint steps per call.
#[derive(Clone, Debug)]
pub struct DiscOverTexture {
    /// Radiance of the static texture, e-/us per pixel (`rows x cols`, standard layout).
    texture: Array2<f32>,
    /// The disc: its radius, path, radiance and sub-steps (its background radiance is
    /// not used: the texture is the background).
    pub disc: MovingDisc,
    /// Name of the texture in provenance (e.g. [`super::sensor::BackgroundTexture::KIND`]).
    pub texture_kind: String,
    /// Seed the texture was drawn from, when it was drawn (provenance only).
    pub texture_seed: Option<u64>,
    /// The scene's `kind` in provenance: "disc-over-texture" (a bright disc), or
    /// [`OCCLUDER_KIND`] (a dark one).
    pub kind: &'static str,
}

/// The `kind` of a [`DiscOverTexture`] whose disc is darker than its texture.
pub const OCCLUDER_KIND: &str = "occluder";

impl DiscOverTexture {
    /// A disc of `radius_px` and radiance `disc_e_per_us` crossing the static `texture`
    /// (radiance, e-/us per pixel, `rows x cols`), 8 sub-steps per call, texture kind
    /// "image" and no seed (see [`DiscOverTexture::with_texture_provenance`]). The
    /// texture must be non-empty and finite, the radius positive, the disc's radiance
    /// finite and non-negative, its start and velocity finite.
    pub fn new(
        texture: Array2<f32>,
        radius_px: f64,
        start_px: (f64, f64),
        velocity_px_per_us: (f64, f64),
        disc_e_per_us: f64,
    ) -> Result<DiscOverTexture, SimError> {
        if texture.is_empty() {
            return Err(invalid("texture", format!("{:?}", texture.dim()), "an image of at least 1 x 1 pixels"));
        }
        if texture.iter().any(|v| !v.is_finite()) {
            return Err(invalid("texture", "non-finite radiance", "finite radiance in e-/us per pixel"));
        }
        if !(radius_px.is_finite() && radius_px > 0.0) {
            return Err(invalid("disc_radius_px", radius_px, "a positive radius in pixels"));
        }
        if !(disc_e_per_us.is_finite() && disc_e_per_us >= 0.0) {
            return Err(invalid("disc_e_per_us", disc_e_per_us, "a finite, non-negative radiance in photo-electrons per microsecond per pixel"));
        }
        if ![start_px.0, start_px.1, velocity_px_per_us.0, velocity_px_per_us.1].iter().all(|v| v.is_finite()) {
            return Err(invalid(
                "start_px + velocity_px_per_us",
                format!("{start_px:?}, {velocity_px_per_us:?}"),
                "a finite start (pixels) and velocity (pixels per microsecond)",
            ));
        }
        let texture = texture.as_standard_layout().into_owned();
        let (rows, cols) = texture.dim();
        let disc = MovingDisc::new(rows, cols, radius_px, start_px, velocity_px_per_us, disc_e_per_us);
        Ok(DiscOverTexture { texture, disc, texture_kind: "image".into(), texture_seed: None, kind: "disc-over-texture" })
    }

    /// The same scene with the texture's provenance: its `kind` and the `seed` it was
    /// drawn from (recorded by [`Scene::describe`]).
    pub fn with_texture_provenance(mut self, kind: &str, seed: Option<u64>) -> DiscOverTexture {
        self.texture_kind = kind.to_string();
        self.texture_seed = seed;
        self
    }

    /// The same scene named `kind` in provenance (e.g. [`OCCLUDER_KIND`]).
    pub fn with_kind(mut self, kind: &'static str) -> DiscOverTexture {
        self.kind = kind;
        self
    }

    /// Centre (row, col) of the disc in pixels at time `t_us`.
    pub fn centre_px(&self, t_us: f64) -> (f64, f64) {
        self.disc.centre_px(t_us)
    }

    /// The static texture's radiance, e-/us per pixel (`rows x cols`).
    pub fn texture(&self) -> ndarray::ArrayView2<'_, f32> {
        self.texture.view()
    }

    /// Mean radiance of the texture, e-/us per pixel.
    pub fn texture_mean_e_per_us(&self) -> f64 {
        self.texture.iter().map(|&v| v as f64).sum::<f64>() / self.texture.len() as f64
    }
}

impl Scene for DiscOverTexture {
    fn size(&self) -> (usize, usize) {
        self.texture.dim()
    }

    fn integrate(&self, t0_us: f64, t1_us: f64, out: &mut [f32]) {
        let (rows, cols) = self.texture.dim();
        let tex = self.texture.as_slice().expect("standard layout");
        let span = (t1_us - t0_us).max(0.0);
        let w = span as f32;
        for (o, &v) in out.iter_mut().zip(tex) {
            *o = v * w;
        }
        let disc = &self.disc;
        let n = disc.substeps.max(1);
        let dt = span / n as f64;
        let per_hit = dt / (DISC_SAMPLES * DISC_SAMPLES) as f64;
        for j in 0..n {
            let (cr, cc) = disc.centre_px(t0_us + (j as f64 + 0.5) * dt);
            disc_coverage(rows, cols, cr, cc, disc.radius_px, |k, hits| {
                out[k] += ((disc.disc_e_per_us - tex[k] as f64) * per_hit * hits as f64) as f32;
            });
        }
    }

    fn describe(&self) -> toml::Table {
        let (rows, cols) = self.texture.dim();
        let mut t = toml::Table::new();
        let disc = &self.disc;
        t.insert("kind".into(), self.kind.into());
        t.insert("radius_px".into(), disc.radius_px.into());
        t.insert("start_px".into(), vec![disc.start_px.0, disc.start_px.1].into());
        t.insert("velocity_px_per_us".into(), vec![disc.velocity_px_per_us.0, disc.velocity_px_per_us.1].into());
        t.insert("disc_e_per_us".into(), disc.disc_e_per_us.into());
        t.insert("substeps".into(), (disc.substeps as i64).into());
        let mut tx = toml::Table::new();
        tx.insert("kind".into(), self.texture_kind.clone().into());
        if let Some(seed) = self.texture_seed {
            tx.insert("seed".into(), (seed as i64).into());
        }
        tx.insert("mean_e_per_us".into(), self.texture_mean_e_per_us().into());
        tx.insert("rows".into(), (rows as i64).into());
        tx.insert("cols".into(), (cols as i64).into());
        tx.insert("in_truth".into(), true.into());
        t.insert("texture".into(), tx.into());
        let shade = if disc.disc_e_per_us < self.texture_mean_e_per_us() { "a dark" } else { "a bright" };
        t.insert("note".into(), format!("{shade} disc occludes a static texture; both are in the scene and in truth.npy").into());
        t
    }
}

/// A stack of frames (`frames x rows x cols`, radiance in e-/us per pixel), frame `f`
/// shown during `[f * frame_interval_us, (f+1) * frame_interval_us)`. After the last
/// frame the stack loops or holds the last frame; before t = 0 it shows frame 0.
/// Piecewise constant in time, so the integral is exact.
#[derive(Clone, Debug)]
pub struct ImageStack {
    frames: Array3<f32>,
    frame_interval_us: f64,
    looping: bool,
}

impl ImageStack {
    pub fn new(frames: Array3<f32>, frame_interval_us: f64, looping: bool) -> Result<ImageStack, SimError> {
        if frames.is_empty() {
            return Err(invalid("frames", format!("{:?}", frames.dim()), "at least one frame of at least 1 x 1 pixels"));
        }
        if !(frame_interval_us.is_finite() && frame_interval_us > 0.0) {
            return Err(invalid("frame_interval_us", frame_interval_us, "a positive, finite time in microseconds"));
        }
        if frames.iter().any(|v| !v.is_finite()) {
            return Err(invalid("frames", "non-finite radiance", "finite radiance in e-/us per pixel"));
        }
        let frames = frames.as_standard_layout().into_owned();
        Ok(ImageStack { frames, frame_interval_us, looping })
    }

    /// One static image (radiance in e-/us per pixel) shown forever.
    pub fn still(image: Array2<f32>) -> Result<ImageStack, SimError> {
        let (r, c) = image.dim();
        ImageStack::new(image.into_shape_with_order((1, r, c)).expect("1 x rows x cols"), 1.0, false)
    }

    fn frame_of(&self, index: i64) -> usize {
        let n = self.frames.dim().0 as i64;
        if index < 0 {
            0
        } else if self.looping {
            (index % n) as usize
        } else {
            index.min(n - 1) as usize
        }
    }
}

impl Scene for ImageStack {
    fn size(&self) -> (usize, usize) {
        let (_, r, c) = self.frames.dim();
        (r, c)
    }

    fn integrate(&self, t0_us: f64, t1_us: f64, out: &mut [f32]) {
        out.fill(0.0);
        let (n, r, c) = self.frames.dim();
        let data = self.frames.as_slice().expect("standard layout");
        let dt = self.frame_interval_us;
        let mut t = t0_us;
        while t < t1_us {
            let mut idx = (t / dt).floor() as i64;
            if (idx + 1) as f64 * dt <= t {
                idx += 1; // round-off: t sits on the boundary
            }
            let end = if idx < 0 {
                0.0f64.min(t1_us) // frame 0 until t = 0
            } else if !self.looping && idx >= n as i64 - 1 {
                t1_us // the last frame holds
            } else {
                ((idx + 1) as f64 * dt).min(t1_us)
            };
            let f = self.frame_of(idx);
            let w = (end - t) as f32;
            for (o, &v) in out.iter_mut().zip(&data[f * r * c..(f + 1) * r * c]) {
                *o += v * w;
            }
            t = end;
        }
    }

    fn describe(&self) -> toml::Table {
        let (n, r, c) = self.frames.dim();
        let mut t = toml::Table::new();
        t.insert("kind".into(), "image-stack".into());
        t.insert("frames".into(), (n as i64).into());
        t.insert("rows".into(), (r as i64).into());
        t.insert("cols".into(), (c as i64).into());
        t.insert("frame_interval_us".into(), self.frame_interval_us.into());
        t.insert("looping".into(), self.looping.into());
        t
    }
}

/// Name of [`texture`] in provenance.
pub const TEXTURE_KIND: &str = "blobs-and-rectangles";

/// The random stream of a texture drawn from a set-up's seed ([`derive_seed`]).
pub(crate) const TEXTURE_STREAM: u64 = 2;

/// A textured still scene (`rows x cols`, radiance in e-/us per pixel, mean
/// `mean_e_per_us`): six smooth blobs and three striped rectangles on a floor, drawn
/// from `rng_seed` (the bench background of `super::sensor` and the dense scene
/// [`DiscOverTexture`] use it).
pub fn texture(rows: usize, cols: usize, mean_e_per_us: f64, rng_seed: u64) -> Array2<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(rng_seed);
    let (r, c) = (rows as f64, cols as f64);
    let side = r.min(c);
    let mut img = vec![0.25f64; rows * cols];
    // Smooth blobs.
    for _ in 0..6 {
        let (cy, cx) = (rng.gen_range(0.0..r), rng.gen_range(0.0..c));
        let sigma = rng.gen_range(0.06..0.2) * side;
        let amp = rng.gen_range(0.3..1.0);
        for i in 0..rows {
            for j in 0..cols {
                let d2 = (i as f64 - cy).powi(2) + (j as f64 - cx).powi(2);
                img[i * cols + j] += amp * (-0.5 * d2 / (sigma * sigma)).exp();
            }
        }
    }
    // Rectangles with stripes.
    for _ in 0..3 {
        let (h, w) = (rng.gen_range(0.1..0.35) * r, rng.gen_range(0.1..0.35) * c);
        let (y0, x0) = (rng.gen_range(0.0..(r - h).max(1.0)), rng.gen_range(0.0..(c - w).max(1.0)));
        let amp = rng.gen_range(0.3..0.8);
        let period = rng.gen_range(4.0..10.0);
        let angle = rng.gen_range(0.0..std::f64::consts::PI);
        let (ca, sa) = (angle.cos(), angle.sin());
        for i in (y0.floor() as usize)..((y0 + h).ceil() as usize).min(rows) {
            for j in (x0.floor() as usize)..((x0 + w).ceil() as usize).min(cols) {
                let phase = 2.0 * std::f64::consts::PI * (i as f64 * sa + j as f64 * ca) / period;
                img[i * cols + j] += amp * (0.75 + 0.25 * phase.cos());
            }
        }
    }
    let mean = img.iter().sum::<f64>() / img.len().max(1) as f64;
    let scale = if mean > 0.0 { mean_e_per_us / mean } else { 0.0 };
    Array2::from_shape_vec((rows, cols), img.iter().map(|&v| (v * scale) as f32).collect()).expect("rows x cols")
}

/// A seed for item `index` of stream `stream` of `seed` (SplitMix64 finaliser), so
/// that frames, defects and background never share a ChaCha stream with the capture's
/// noise (seeded by `seed` itself).
pub(crate) fn derive_seed(seed: u64, stream: u64, index: u64) -> u64 {
    let mut z = seed ^ stream.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ index.wrapping_add(1).wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sum(v: &[f32]) -> f64 {
        v.iter().map(|&x| x as f64).sum()
    }

    #[test]
    fn square_wave_on_fraction_is_exact() {
        // Period 10, duty 0.3, phase 2: on during [2, 5), [12, 15), ...
        let m = |a, b| square_wave_mean(a, b, 10.0, 0.3, 2.0);
        assert!((m(0.0, 10.0) - 0.3).abs() < 1e-12);
        assert!((m(2.0, 5.0) - 1.0).abs() < 1e-12);
        assert!(m(5.0, 12.0).abs() < 1e-12);
        assert!((m(4.0, 13.0) - 2.0 / 9.0).abs() < 1e-12);
        assert!((m(-8.0, -5.0) - 1.0).abs() < 1e-12, "negative times wrap");
        assert!((m(0.0, 1000.0) - 0.3).abs() < 1e-12);
        // Sub-interval sums add up to the whole (continuity of the on-time).
        let whole = m(1.3, 47.9) * (47.9 - 1.3);
        let parts: f64 = (0..10)
            .map(|k| {
                let (a, b) = (1.3 + k as f64 * 4.66, 1.3 + (k + 1) as f64 * 4.66);
                m(a, b) * (b - a)
            })
            .sum();
        assert!((whole - parts).abs() < 1e-9);
    }

    #[test]
    fn led_integral_matches_waveform_and_brightness() {
        let leds = LedArray::new(
            16,
            32,
            LedLine { leds: 3, spacing_px: 8.0, radius_px: 1.2, period_us: vec![10.0, 20.0, 40.0], duty: 0.5, phase_us: vec![0.0], e_per_us: 100.0 },
        )
        .unwrap();
        let mut out = vec![0.0; 16 * 32];
        leds.integrate(0.0, 15.0, &mut out);
        // LED 0 (period 10): on [0,5) and [10,15): 10 us; LED 1: [0,10): 10 us;
        // LED 2: [0,15): 15 us. Total 100 e-/us * 35 us.
        assert!((sum(&out) - 3500.0).abs() < 1e-2, "{}", sum(&out));
        let lit: f64 = leds.spot(2).iter().map(|&(i, _)| out[i] as f64).sum();
        assert!(lit >= 1500.0 - 1e-2, "{lit}");
        assert!((leds.waveform(0, 0.0, 15.0) - 10.0 / 15.0).abs() < 1e-12);
        // The LEDs lie on the centre row, symmetric about the centre column.
        let centroid = |k: usize| {
            let s = leds.spot(k);
            let w: f64 = s.iter().map(|&(_, v)| v as f64).sum();
            let r: f64 = s.iter().map(|&(i, v)| (i / 32) as f64 * v as f64).sum::<f64>() / w;
            let c: f64 = s.iter().map(|&(i, v)| (i % 32) as f64 * v as f64).sum::<f64>() / w;
            (r + 0.5, c + 0.5)
        };
        let (r1, c1) = centroid(1);
        assert!((r1 - 8.5).abs() < 1e-4 && (c1 - 16.5).abs() < 1e-4, "{r1},{c1}");
        assert_eq!(leds.centre_px(1), (8.5, 16.5));
        assert!((centroid(0).1 - leds.centre_px(0).1).abs() < 1e-4);
        assert!((centroid(2).1 - centroid(0).1 - 16.0).abs() < 1e-4);
    }

    #[test]
    fn led_parameters_are_checked() {
        let e = LedArray::new(
            16,
            32,
            LedLine { leds: 4, spacing_px: 6.0, radius_px: 1.5, period_us: vec![1.0, 2.0], duty: 0.5, phase_us: vec![0.0], e_per_us: 1.0 },
        )
        .unwrap_err();
        assert!(e.to_string().contains("period_us"), "{e}");
        let e =
            LedArray::new(16, 32, LedLine { leds: 4, spacing_px: 60.0, radius_px: 1.5, period_us: vec![1.0], duty: 0.5, phase_us: vec![0.0], e_per_us: 1.0 })
                .unwrap_err();
        assert!(e.to_string().contains("spacing_px"), "{e}");
        let e =
            LedArray::new(16, 32, LedLine { leds: 4, spacing_px: 6.0, radius_px: 1.5, period_us: vec![1.0], duty: 1.5, phase_us: vec![0.0], e_per_us: 1.0 })
                .unwrap_err();
        assert!(e.to_string().contains("duty"), "{e}");
    }

    #[test]
    fn moving_disc_conserves_flux_and_moves() {
        let disc = MovingDisc::new(32, 32, 3.0, (16.0, 8.0), (0.0, 0.5), 2.0);
        let mut out = vec![0.0; 32 * 32];
        disc.integrate(0.0, 10.0, &mut out);
        // Flux: area * radiance * time (anti-aliasing is accurate to ~1%).
        let expect = std::f64::consts::PI * 9.0 * 2.0 * 10.0;
        assert!((sum(&out) / expect - 1.0).abs() < 0.03, "{} vs {expect}", sum(&out));
        // The integrated centroid is the centre at the mid time (col 8 + 0.5*5 = 10.5).
        let w = sum(&out);
        let c: f64 = out.iter().enumerate().map(|(i, &v)| ((i % 32) as f64 + 0.5) * v as f64).sum::<f64>() / w;
        assert!((c - 10.5).abs() < 0.05, "{c}");
        // Background is exact and occluded by the disc.
        let mut bg = disc.clone();
        bg.background_e_per_us = 0.5;
        bg.integrate(0.0, 10.0, &mut out);
        assert!((out[0] - 5.0).abs() < 1e-6);
        assert!((out[16 * 32 + 10] - 20.0).abs() < 1e-4, "disc centre stays covered: {}", out[16 * 32 + 10]);
    }

    #[test]
    fn the_moving_disc_bounces_and_never_leaves() {
        let disc = MovingDisc::new(20, 40, 3.0, (8.0, 30.0), (0.0, 1.0), 1.0);
        // Straight until the edge (col 37), then back.
        assert_eq!(disc.centre_px(5.0), (8.0, 35.0));
        assert_eq!(disc.centre_px(9.0), (8.0, 35.0));
        assert_eq!(disc.centre_px(7.0 + 34.0), (8.0, 3.0));
        for t in 0..400 {
            let mut out = vec![0.0; 20 * 40];
            disc.integrate(t as f64, t as f64 + 1.0, &mut out);
            let expect = std::f64::consts::PI * 9.0;
            assert!((sum(&out) / expect - 1.0).abs() < 0.03, "t = {t}: the whole disc is in the field");
        }
        assert_eq!(bounce(-3.0, 0.0, 10.0), 3.0);
        assert_eq!(bounce(23.0, 0.0, 10.0), 3.0);
        assert_eq!(bounce(5.0, 4.0, 4.0), 4.0);
    }

    fn texture(rows: usize, cols: usize) -> Array2<f32> {
        Array2::from_shape_fn((rows, cols), |(i, j)| 1.0 + 0.25 * ((i * 7 + j * 3) % 5) as f32)
    }

    #[test]
    fn disc_over_texture_is_the_texture_where_the_disc_is_not() {
        let tex = texture(16, 24);
        // A disc held still in the top-left corner (pixels 1 and 2 of rows and columns).
        let scene = DiscOverTexture::new(tex.clone(), 1.0, (2.0, 2.0), (0.0, 0.0), 50.0).unwrap();
        assert_eq!(scene.size(), (16, 24));
        let mut out = vec![-1.0; 16 * 24];
        let (t0, t1) = (3.0, 10.5);
        scene.integrate(t0, t1, &mut out);
        let span = (t1 - t0) as f32;
        for (k, (o, &v)) in out.iter().zip(tex.iter()).enumerate() {
            if k / 24 >= 4 || k % 24 >= 4 {
                assert_eq!(*o, v * span, "pixel {k}");
            }
        }
        assert!(out[24 + 1] > tex[[1, 1]] * span, "the disc is there");
        // Empty or reversed intervals integrate to nothing.
        scene.integrate(5.0, 5.0, &mut out);
        assert!(out.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn disc_as_bright_as_a_flat_texture_leaves_it_flat() {
        let flat = Array2::from_elem((20, 20), 3.0f32);
        let scene = DiscOverTexture::new(flat, 4.0, (10.0, 6.0), (0.05, 0.3), 3.0).unwrap();
        let mut out = vec![0.0; 400];
        scene.integrate(0.0, 20.0, &mut out);
        for &v in &out {
            assert!((v - 60.0).abs() < 1e-3, "{v}");
        }
    }

    #[test]
    fn static_disc_occludes_the_texture() {
        let tex = texture(32, 32);
        let scene = DiscOverTexture::new(tex.clone(), 5.0, (16.0, 16.0), (0.0, 0.0), 40.0).unwrap();
        let mut out = vec![0.0; 32 * 32];
        scene.integrate(1.0, 3.0, &mut out);
        // Pixels wholly inside the disc have the disc's radiance, those wholly outside
        // the texture's; edge pixels lie between.
        for i in 0..32 {
            for j in 0..32 {
                let (y, x) = (i as f64 + 0.5 - 16.0, j as f64 + 0.5 - 16.0);
                let d = (y * y + x * x).sqrt();
                let v = out[i * 32 + j];
                let t = 2.0 * tex[[i, j]];
                if d < 5.0 - 0.75 {
                    assert!((v - 80.0).abs() < 1e-4, "inside ({i}, {j}): {v}");
                } else if d > 5.0 + 0.75 {
                    assert_eq!(v, t, "outside ({i}, {j})");
                } else {
                    assert!(v >= t - 1e-4 && v <= 80.0 + 1e-4, "edge ({i}, {j}): {v}");
                }
            }
        }
        // The covered area is the disc's (anti-aliasing accurate to ~1%).
        let excess: f64 = out.iter().zip(tex.iter()).map(|(&o, &t)| (o - 2.0 * t) as f64 / (80.0 - 2.0 * t as f64)).sum();
        assert!((excess / (std::f64::consts::PI * 25.0) - 1.0).abs() < 0.02, "{excess}");
    }

    #[test]
    fn moving_disc_over_texture_moves_and_describes_itself() {
        let flat = Array2::from_elem((32, 48), 1.0f32);
        let scene = DiscOverTexture::new(flat, 3.0, (16.0, 8.0), (0.0, 0.5), 5.0).unwrap().with_texture_provenance("test", Some(7));
        assert_eq!(scene.centre_px(10.0), (16.0, 13.0));
        let mut out = vec![0.0; 32 * 48];
        scene.integrate(0.0, 10.0, &mut out);
        // The excess over the texture is the disc's, centred on the mid-time centre.
        let ex: Vec<f64> = out.iter().map(|&v| v as f64 - 10.0).collect();
        let w: f64 = ex.iter().sum();
        let expect = std::f64::consts::PI * 9.0 * 4.0 * 10.0;
        assert!((w / expect - 1.0).abs() < 0.03, "{w} vs {expect}");
        let c: f64 = ex.iter().enumerate().map(|(i, &v)| ((i % 48) as f64 + 0.5) * v).sum::<f64>() / w;
        assert!((c - 10.5).abs() < 0.05, "{c}");
        let d = scene.describe();
        assert_eq!(d["kind"].as_str(), Some("disc-over-texture"));
        assert_eq!(d["texture"]["kind"].as_str(), Some("test"));
        assert_eq!(d["texture"]["seed"].as_integer(), Some(7));
        assert_eq!(d["texture"]["mean_e_per_us"].as_float(), Some(1.0));
        assert_eq!(d["disc_e_per_us"].as_float(), Some(5.0));
        let e = DiscOverTexture::new(Array2::from_elem((4, 4), f32::NAN), 1.0, (0.0, 0.0), (0.0, 0.0), 1.0).unwrap_err();
        assert!(e.to_string().contains("texture"), "{e}");
        let e = DiscOverTexture::new(Array2::zeros((4, 4)), 0.0, (0.0, 0.0), (0.0, 0.0), 1.0).unwrap_err();
        assert!(e.to_string().contains("radius"), "{e}");
    }

    #[test]
    fn image_stack_is_piecewise_constant_loop_and_hold() {
        let frames = Array3::from_shape_fn((3, 1, 2), |(f, _, c)| (f * 10 + c) as f32);
        let hold = ImageStack::new(frames.clone(), 2.0, false).unwrap();
        let mut out = vec![0.0; 2];
        hold.integrate(1.0, 5.0, &mut out); // 1 us of f0, 2 of f1, 1 of f2
        assert_eq!(out, vec![1.0 * 0.0 + 2.0 * 10.0 + 1.0 * 20.0, 1.0 * 1.0 + 2.0 * 11.0 + 21.0]);
        hold.integrate(10.0, 20.0, &mut out); // held last frame
        assert_eq!(out, vec![200.0, 210.0]);
        hold.integrate(-3.0, 1.0, &mut out); // frame 0 before t = 0
        assert_eq!(out, vec![0.0, 4.0]);
        let looped = ImageStack::new(frames, 2.0, true).unwrap();
        looped.integrate(6.0, 9.0, &mut out); // f0 for 2 us, f1 for 1 us
        assert_eq!(out, vec![10.0, 2.0 + 11.0]);
        // Sub-interval integrals add up.
        let mut a = vec![0.0; 2];
        let mut b = vec![0.0; 2];
        looped.integrate(0.3, 7.1, &mut a);
        looped.integrate(7.1, 13.9, &mut b);
        looped.integrate(0.3, 13.9, &mut out);
        for k in 0..2 {
            assert!((a[k] + b[k] - out[k]).abs() < 1e-4);
        }
    }

    #[test]
    fn midpoint_rule_is_exact_for_linear_radiance() {
        let mut out = vec![0.0; 2];
        let mut scratch = Vec::new();
        // L(t) = (t, 3): integral over [1, 5) = (12, 12).
        integrate_midpoint(
            |t, b| {
                b[0] = t as f32;
                b[1] = 3.0;
            },
            1.0,
            5.0,
            3,
            &mut out,
            &mut scratch,
        );
        assert!((out[0] - 12.0).abs() < 1e-5 && (out[1] - 12.0).abs() < 1e-5, "{out:?}");
    }
}
