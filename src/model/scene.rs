//! Only what a scene needs. The `[scene]` table of `capture.toml` is free-form
//! provenance; these typed keys, when present, declare what the scene is, and the
//! reconstruction then solves for that alone:
//!
//! | key | meaning | what is left out |
//! |---|---|---|
//! | `colour = "grey"` | the scene is grey | an RGB raw is averaged over channels (with the mean of the unit-sum PSFs) and solved once, not three times |
//! | `support = [r0, r1, c0, c1]` | light comes only from rows `r0..r1`, columns `c0..c1` of the video grid | unknowns outside the box (an operator that embeds the box into the grid) |
//! | `frames = [k0, k1]` | the scene is dark outside frames `k0..k1` | the other frames (shutter weights restricted to the window) |
//! | `static = true` | nothing moves | all frames but one (one frame, repeated in time by the operator); temporal TV |
//! | `tv_weights = [t, y, x]` | TV weight per axis (relative to tau) | axes of weight 0 leave the TV term |
//! | `static_background = true` | a still scene with something moving over it: `v_k = s + d_k` | nothing: one static image is added to the unknowns, and the dynamic part `d` gets TV and L1 ([`crate::model::static_dynamic`]) |
//!
//! `static_background` left out is the capture's default ([`SceneSpec::static_dynamic`]):
//! the static + dynamic model when key frames are solved (they show the still scene),
//! else the plain video; `static_background = false` asks for the plain video.
//! Other keys of the table are provenance and are not read (an integer `frames` is the
//! image-stack scene's frame count, not a window). Ranges are half-open.

use crate::model::op::{Operator, ShutterConvolution};
use crate::model::shutter::TimingError;
use serde::Serialize;
use std::ops::Range;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Colour {
    /// As many channels as the raw image has.
    #[default]
    AsCaptured,
    Grey,
}

/// The typed declaration of a scene.
#[derive(Clone, Debug, PartialEq, Serialize, Default)]
pub struct SceneSpec {
    pub colour: Colour,
    pub support: Option<[usize; 4]>,
    pub frames: Option<[usize; 2]>,
    #[serde(rename = "static")]
    pub static_scene: bool,
    pub tv_weights: Option<[f32; 3]>,
    /// The static + dynamic model (`v_k = s + d_k`) as declared; `None`: the
    /// capture's default ([`SceneSpec::static_dynamic`]).
    pub static_background: Option<bool>,
    /// Solve the whole grid even where a sparse scene's still image would restrict the
    /// video to a support (`--full-grid`; [`crate::solve::support`] is the solver's).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub whole_grid: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("[scene] {field} = {value}: expected {expected}")]
    Invalid { field: &'static str, value: String, expected: String },
    #[error("{0}")]
    Timing(#[from] TimingError),
}

pub fn invalid(field: &'static str, value: impl std::fmt::Display, expected: impl Into<String>) -> SceneError {
    SceneError::Invalid { field, value: value.to_string(), expected: expected.into() }
}

fn uints<const N: usize>(t: &toml::Table, field: &'static str, expected: &str) -> Result<Option<[usize; N]>, SceneError> {
    let Some(v) = t.get(field) else { return Ok(None) };
    let arr = v.as_array().ok_or_else(|| invalid(field, v, expected))?;
    if arr.len() != N {
        return Err(invalid(field, v, expected));
    }
    let mut out = [0usize; N];
    for (o, x) in out.iter_mut().zip(arr) {
        match x.as_integer() {
            Some(i) if i >= 0 => *o = i as usize,
            _ => return Err(invalid(field, v, expected)),
        }
    }
    Ok(Some(out))
}

/// The typed keys of a `[scene]` table: the declarations.
pub const KEYS: [&str; 6] = ["colour", "support", "frames", "static", "tv_weights", "static_background"];

/// Edit distance of two short keys (insertions, deletions, substitutions).
fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let here = (prev + usize::from(ca != cb)).min(row[j] + 1).min(row[j + 1] + 1);
            prev = row[j + 1];
            row[j + 1] = here;
        }
    }
    row[b.len()]
}

impl SceneSpec {
    /// Whether the scene is solved with the static + dynamic model: as declared, else
    /// when nothing else is declared and either key frames are solved with the raw (they
    /// show the still scene) or `mostly_still` says a still image explains the raw (a
    /// still scene with something moving over it). On such scenes the model keeps the
    /// motion the plain video loses (docs/dense-scenes.md, docs/keyframes.md).
    /// `mostly_still` is asked only when the answer depends on it.
    pub fn static_dynamic(&self, keyframes: bool, mostly_still: impl FnOnce() -> bool) -> bool {
        self.static_background.unwrap_or_else(|| self.is_plain() && (keyframes || mostly_still()))
    }

    /// Nothing declared that restricts or changes the plain video
    /// (`static_background = false` asks for the plain video itself).
    pub fn is_plain(&self) -> bool {
        self.static_background != Some(true) && SceneSpec { static_background: None, whole_grid: false, ..self.clone() } == SceneSpec::default()
    }

    /// A key given as a declaration (`--scene KEY=VALUE`): one of [`KEYS`], else refused
    /// with the known keys listed.
    pub fn check_key(key: &str) -> Result<(), SceneError> {
        if KEYS.contains(&key) {
            return Ok(());
        }
        Err(invalid("key", format!("{key:?}"), format!("one of the declarations {}", KEYS.join(", "))))
    }

    /// Read the typed keys of a `[scene]` table (absent table: nothing declared). Other
    /// keys are provenance, but one within two letters of a declaration is a typo of it
    /// (`static_backgroud`) and is refused rather than ignored.
    pub fn from_table(t: Option<&toml::Table>) -> Result<SceneSpec, SceneError> {
        let Some(t) = t else { return Ok(SceneSpec::default()) };
        if let Some((key, near)) = t.keys().filter(|k| !KEYS.contains(&k.as_str())).find_map(|k| KEYS.iter().find(|d| distance(k, d) <= 2).map(|d| (k, d))) {
            return Err(invalid("key", format!("{key:?}"), format!("a declaration spelt as one of {} (did you mean {near}?)", KEYS.join(", "))));
        }
        let mut s = SceneSpec::default();
        if let Some(v) = t.get("colour") {
            s.colour = match v.as_str() {
                Some("grey") | Some("gray") => Colour::Grey,
                Some("rgb") | Some("as-captured") => Colour::AsCaptured,
                _ => return Err(invalid("colour", v, "\"grey\" or \"rgb\"")),
            };
        }
        s.support = uints::<4>(t, "support", "[r0, r1, c0, c1], non-negative integers with r0 < r1, c0 < c1")?;
        if let Some([r0, r1, c0, c1]) = s.support {
            if r0 >= r1 || c0 >= c1 {
                return Err(invalid("support", format!("[{r0}, {r1}, {c0}, {c1}]"), "r0 < r1 and c0 < c1"));
            }
        }
        // An integer `frames` is the image-stack scene's provenance (its frame count),
        // not a declaration; a window is an array.
        if t.get("frames").is_some_and(|v| !v.is_integer()) {
            s.frames = uints::<2>(t, "frames", "[k0, k1], non-negative integers with k0 < k1")?;
        }
        if let Some([k0, k1]) = s.frames {
            if k0 >= k1 {
                return Err(invalid("frames", format!("[{k0}, {k1}]"), "k0 < k1"));
            }
        }
        if let Some(v) = t.get("static") {
            s.static_scene = v.as_bool().ok_or_else(|| invalid("static", v, "true or false"))?;
        }
        if let Some(v) = t.get("static_background") {
            s.static_background = Some(v.as_bool().ok_or_else(|| invalid("static_background", v, "true or false"))?);
        }
        if s.static_background == Some(true) {
            let clash = [
                (s.static_scene, "static = true"),
                (s.support.is_some(), "support"),
                (s.frames.is_some(), "frames"),
                (s.colour == Colour::Grey, "colour = \"grey\""),
            ]
            .into_iter()
            .find(|(c, _)| *c);
            if let Some((_, key)) = clash {
                return Err(invalid(
                    "static_background",
                    true,
                    format!("no other declaration beside it but tv_weights (found {key}); declare one or the other"),
                ));
            }
        }
        if let Some(v) = t.get("tv_weights") {
            let expected = "[t, y, x], three finite non-negative numbers";
            let arr = v.as_array().filter(|a| a.len() == 3).ok_or_else(|| invalid("tv_weights", v, expected))?;
            let mut w = [0f32; 3];
            for (o, x) in w.iter_mut().zip(arr) {
                let f = x.as_float().or_else(|| x.as_integer().map(|i| i as f64)).ok_or_else(|| invalid("tv_weights", v, expected))?;
                if !(f.is_finite() && f >= 0.0) {
                    return Err(invalid("tv_weights", v, expected));
                }
                *o = f as f32;
            }
            s.tv_weights = Some(w);
        }
        Ok(s)
    }

    /// Write the typed keys into a `[scene]` table (keeping its other keys).
    pub fn write_into(&self, t: &mut toml::Table) {
        use toml::Value;
        if self.colour == Colour::Grey {
            t.insert("colour".into(), Value::String("grey".into()));
        }
        let ints = |v: &[usize]| Value::Array(v.iter().map(|&x| Value::Integer(x as i64)).collect());
        if let Some(s) = self.support {
            t.insert("support".into(), ints(&s));
        }
        if let Some(f) = self.frames {
            t.insert("frames".into(), ints(&f));
        }
        if self.static_scene {
            t.insert("static".into(), Value::Boolean(true));
        }
        if let Some(b) = self.static_background {
            t.insert("static_background".into(), Value::Boolean(b));
        }
        if let Some(w) = self.tv_weights {
            t.insert("tv_weights".into(), Value::Array(w.iter().map(|&x| Value::Float(x as f64)).collect()));
        }
    }
}

/// `A` restricted to a box of rows and columns, optionally one frame repeated in time:
/// `forward = A(embed(x))`, `adjoint = restrict(A^T y)` (summed over frames when static).
pub struct Restricted<A> {
    pub inner: A,
    /// (frames, rows, cols) of the inner operator's input.
    pub full: (usize, usize, usize),
    pub rows: Range<usize>,
    pub cols: Range<usize>,
    pub static_scene: bool,
}

impl<A: Operator> Restricted<A> {
    pub fn new(inner: A, rows: Range<usize>, cols: Range<usize>, static_scene: bool) -> Self {
        let s = inner.input_shape();
        assert_eq!(s.len(), 3, "restricted operator needs a (frames, rows, cols) input");
        let full = (s[0], s[1], s[2]);
        assert!(rows.end <= full.1 && cols.end <= full.2 && !rows.is_empty() && !cols.is_empty());
        Restricted { inner, full, rows, cols, static_scene }
    }
    /// Whether the restriction leaves every unknown in (no support, not static): the
    /// operator is then the inner one, applied without copies.
    pub fn is_identity(&self) -> bool {
        !self.static_scene && self.rows == (0..self.full.1) && self.cols == (0..self.full.2)
    }
    /// (frames, rows, cols) of the unknowns.
    pub fn shape(&self) -> (usize, usize, usize) {
        (if self.static_scene { 1 } else { self.full.0 }, self.rows.len(), self.cols.len())
    }
    /// The full-grid video of a reduced one (zeros outside the support).
    pub fn embed(&self, x: &[f32]) -> Vec<f32> {
        let (k, m, n) = self.full;
        let (kr, mr, nr) = self.shape();
        let mut out = vec![0.0f32; k * m * n];
        for f in 0..k {
            let fs = if self.static_scene { 0 } else { f };
            for r in 0..mr {
                let src = &x[(fs * mr + r) * nr..(fs * mr + r + 1) * nr];
                let o = (f * m + r + self.rows.start) * n + self.cols.start;
                out[o..o + nr].copy_from_slice(src);
            }
        }
        debug_assert_eq!(x.len(), kr * mr * nr);
        out
    }
    /// The reduced unknowns of a full-grid video: the box, averaged over frames when static.
    pub fn restrict(&self, full: &[f32], sum_frames: bool) -> Vec<f32> {
        let (k, m, n) = self.full;
        let (_, mr, nr) = self.shape();
        let mut out = vec![0.0f32; self.shape().0 * mr * nr];
        let mut acc = vec![0.0f64; out.len()];
        for f in 0..k {
            let fs = if self.static_scene { 0 } else { f };
            for r in 0..mr {
                let o = (f * m + r + self.rows.start) * n + self.cols.start;
                for c in 0..nr {
                    acc[(fs * mr + r) * nr + c] += full[o + c] as f64;
                }
            }
        }
        let scale = if self.static_scene && !sum_frames { 1.0 / k as f64 } else { 1.0 };
        for (o, a) in out.iter_mut().zip(acc) {
            *o = (a * scale) as f32;
        }
        out
    }
}

impl<A: Operator> Operator for Restricted<A> {
    /// The inner operator's structure when nothing is restricted.
    fn shutter_convolution(&self) -> Option<ShutterConvolution<'_>> {
        self.inner.shutter_convolution().filter(|_| self.is_identity())
    }
    /// A box of the unknowns only lowers the inner bound; one frame repeated in every
    /// frame is the static image's ([`ShutterConvolution::static_lambda_upper_bound`]).
    fn lipschitz_upper_bound(&self) -> Option<f64> {
        if self.static_scene {
            self.inner.shutter_convolution().map(|s| s.static_lambda_upper_bound())
        } else {
            self.inner.lipschitz_upper_bound()
        }
    }
    fn input_shape(&self) -> Vec<usize> {
        let (k, m, n) = self.shape();
        vec![k, m, n]
    }
    fn output_shape(&self) -> Vec<usize> {
        self.inner.output_shape()
    }
    fn forward(&self, x: &[f32], y: &mut [f32]) {
        if self.is_identity() {
            return self.inner.forward(x, y);
        }
        self.inner.forward(&self.embed(x), y);
    }
    fn adjoint(&self, y: &[f32], x: &mut [f32]) {
        if self.is_identity() {
            return self.inner.adjoint(y, x);
        }
        let (k, m, n) = self.full;
        let mut full = vec![0.0f32; k * m * n];
        self.inner.adjoint(y, &mut full);
        x.copy_from_slice(&self.restrict(&full, true));
    }
}

/// What a declaration removed from the problem.
#[derive(Clone, Debug, Serialize)]
pub struct ScenePlan {
    pub spec: SceneSpec,
    pub channels_captured: usize,
    pub channels_solved: usize,
    /// (frames, rows, cols) of the full video grid and of the solved unknowns.
    pub full_shape: (usize, usize, usize),
    pub solved_shape: (usize, usize, usize),
    /// Frames `k0..k1` of the full grid that the solved frames cover.
    pub frames: (usize, usize),
    pub tv_axes: Vec<&'static str>,
    pub left_out: Vec<String>,
}

impl ScenePlan {
    /// Unknowns over all solved channels, full vs solved.
    pub fn unknowns(&self) -> (usize, usize) {
        let (a, b, c) = self.full_shape;
        let (d, e, f) = self.solved_shape;
        (a * b * c * self.channels_captured, d * e * f * self.channels_solved)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::{adjoint_mismatch, pseudo_random, Dense};

    #[test]
    fn reads_typed_keys_and_names_bad_fields() {
        let t: toml::Table =
            toml::from_str("colour = \"grey\"\nsupport = [1, 5, 2, 7]\nframes = [3, 9]\nstatic = true\ntv_weights = [0, 1, 1.5]\nkind = \"led-array\"")
                .unwrap();
        let s = SceneSpec::from_table(Some(&t)).unwrap();
        assert_eq!(s.colour, Colour::Grey);
        assert_eq!(s.support, Some([1, 5, 2, 7]));
        assert_eq!(s.frames, Some([3, 9]));
        assert!(s.static_scene);
        assert_eq!(s.tv_weights, Some([0.0, 1.0, 1.5]));
        let mut back = toml::Table::new();
        s.write_into(&mut back);
        assert_eq!(SceneSpec::from_table(Some(&back)).unwrap(), s);
        for (text, field) in [
            ("support = [5, 1, 0, 2]", "support"),
            ("frames = [1]", "frames"),
            ("colour = 3", "colour"),
            ("tv_weights = [1, -1, 0]", "tv_weights"),
            ("static = 1", "static"),
        ] {
            let t: toml::Table = toml::from_str(text).unwrap();
            let e = SceneSpec::from_table(Some(&t)).unwrap_err().to_string();
            assert!(e.contains(field) && e.contains("expected"), "{e}");
        }
    }

    #[test]
    fn misspelt_declarations_are_refused_with_the_known_keys() {
        // `static_backgroud = true` was ignored: the full problem was solved, and not a word.
        let t: toml::Table = toml::from_str("static_backgroud = true\nkind = \"led-array\"\nduty = 0.5").unwrap();
        let e = SceneSpec::from_table(Some(&t)).unwrap_err().to_string();
        assert!(e.contains("static_backgroud") && e.contains("did you mean static_background") && e.contains("tv_weights"), "{e}");
        // Provenance keys of the simulator are not declarations and stay allowed.
        let t: toml::Table = toml::from_str("kind = \"led-array\"\nleds = 4\nperiod_us = [1.0]\nspacing_px = 6.0\nframes = 3").unwrap();
        assert_eq!(SceneSpec::from_table(Some(&t)).unwrap(), SceneSpec::default());
        assert!(SceneSpec::check_key("static_background").is_ok());
        let e = SceneSpec::check_key("statik").unwrap_err().to_string();
        assert!(e.contains("statik") && e.contains("support"), "{e}");
    }

    #[test]
    fn static_background_reads_and_refuses_other_declarations() {
        let t: toml::Table = toml::from_str("static_background = true\ntv_weights = [1, 1, 1]").unwrap();
        let s = SceneSpec::from_table(Some(&t)).unwrap();
        assert!(s.static_background == Some(true) && s.static_dynamic(false, || false) && !s.is_plain());
        let mut back = toml::Table::new();
        s.write_into(&mut back);
        assert_eq!(SceneSpec::from_table(Some(&back)).unwrap(), s);
        // Left out: the static + dynamic model with key frames or on a mostly still
        // scene, the plain video otherwise; the still is not asked about with key frames;
        // declared: as declared, nothing asked; declared false: the plain video with key
        // frames too, written back as declared.
        let none = SceneSpec::default();
        let unasked = || -> bool { panic!("the still check is not needed here") };
        assert!(none.static_dynamic(true, unasked) && none.static_dynamic(false, || true) && !none.static_dynamic(false, || false) && none.is_plain());
        assert!(s.static_dynamic(false, unasked));
        // Another declaration is not the plain video: no default model for it.
        for other in [SceneSpec { static_scene: true, ..SceneSpec::default() }, SceneSpec { tv_weights: Some([1.0, 1.0, 1.0]), ..SceneSpec::default() }] {
            assert!(!other.static_dynamic(true, unasked) && !other.static_dynamic(false, unasked));
        }
        let t: toml::Table = toml::from_str("static_background = false").unwrap();
        let plain = SceneSpec::from_table(Some(&t)).unwrap();
        assert!(!plain.static_dynamic(true, unasked) && !plain.static_dynamic(false, unasked) && plain.is_plain());
        let mut back = toml::Table::new();
        plain.write_into(&mut back);
        assert_eq!(back.get("static_background").and_then(|v| v.as_bool()), Some(false));
        for clash in ["static = true", "support = [0, 4, 0, 4]", "frames = [0, 3]", "colour = \"grey\""] {
            let t: toml::Table = toml::from_str(&format!("static_background = true\n{clash}")).unwrap();
            let e = SceneSpec::from_table(Some(&t)).unwrap_err().to_string();
            assert!(e.contains("static_background") && e.contains("expected"), "{e}");
        }
        let t: toml::Table = toml::from_str("static_background = 1").unwrap();
        assert!(SceneSpec::from_table(Some(&t)).unwrap_err().to_string().contains("true or false"));
    }

    #[test]
    fn restricted_operator_is_the_embedded_columns_and_adjoint_exact() {
        let inner = Dense { rows: 7, cols: 2 * 3 * 4, a: pseudo_random(7 * 24, 2) };
        struct Shaped(Dense);
        impl Operator for Shaped {
            fn input_shape(&self) -> Vec<usize> {
                vec![2, 3, 4]
            }
            fn output_shape(&self) -> Vec<usize> {
                vec![7]
            }
            fn forward(&self, x: &[f32], y: &mut [f32]) {
                self.0.forward(x, y)
            }
            fn adjoint(&self, y: &[f32], x: &mut [f32]) {
                self.0.adjoint(y, x)
            }
        }
        // The whole grid, not static: the inner operator itself, bit for bit.
        let whole = Restricted::new(Shaped(inner.clone()), 0..3, 0..4, false);
        assert!(whole.is_identity() && !Restricted::new(Shaped(inner.clone()), 0..3, 0..4, true).is_identity());
        let (x, y) = (pseudo_random(24, 5), pseudo_random(7, 6));
        let (mut a, mut b) = (vec![0.0f32; 7], vec![0.0f32; 7]);
        whole.forward(&x, &mut a);
        inner.forward(&x, &mut b);
        assert_eq!(a, b);
        let (mut a, mut b) = (vec![0.0f32; 24], vec![0.0f32; 24]);
        whole.adjoint(&y, &mut a);
        inner.adjoint(&y, &mut b);
        assert_eq!(a, b);
        for st in [false, true] {
            let r = Restricted::new(Shaped(inner.clone()), 1..3, 1..3, st);
            let x = pseudo_random(r.input_len(), 3);
            let y = pseudo_random(7, 4);
            assert!(adjoint_mismatch(&r, &x, &y) < 1e-6);
            // Column j of the restricted operator is the sum of the inner columns it embeds into.
            let d = Dense::from_operator(&r);
            let e = r.embed(&{
                let mut v = vec![0.0; r.input_len()];
                v[1] = 1.0;
                v
            });
            for i in 0..7 {
                let want: f32 = (0..24).map(|j| inner.a[i * 24 + j] * e[j]).sum();
                assert!((d.a[i * d.cols + 1] - want).abs() < 1e-5);
            }
        }
    }
}
