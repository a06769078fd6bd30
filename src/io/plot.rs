//! Line plots (e.g. PSNR against run time, spectra) as SVG or PNG, in pure Rust.
//!
//! The chart is drawn by `plotters` into SVG (text stays text); PNG is that SVG rendered
//! by `resvg` with DejaVu Sans embedded from the `dejavu` crate, so no system font
//! library is involved.

use std::path::Path;
use std::sync::{Arc, OnceLock};

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use resvg::{tiny_skia, usvg};

use super::atomic::write_atomic;
use super::error::IoError;
use super::formats::image_format::extension;
use super::formats::png::encode_png8;

/// One named curve of a plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// (x, y) points, drawn joined in the given order. Non-finite points, and non-positive
    /// ones on a logarithmic axis, are left out.
    pub points: Vec<(f64, f64)>,
}

/// What [`plot_lines`] draws. Put units in the axis labels, e.g. `"run time (s)"`.
#[derive(Debug, Clone, PartialEq)]
pub struct PlotSpec {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// Picture size in pixels (width, height); SVG user units for SVG.
    pub size: (u32, u32),
}

impl Default for PlotSpec {
    fn default() -> Self {
        PlotSpec { title: String::new(), x_label: String::new(), y_label: String::new(), series: Vec::new(), log_x: false, log_y: false, size: (800, 500) }
    }
}

/// Colours of the series, in order (cycled when there are more series).
pub const SERIES_COLOURS: [[u8; 3]; 6] = [[31, 119, 180], [214, 39, 40], [44, 160, 44], [255, 127, 14], [148, 103, 189], [23, 190, 207]];

/// Font family name the SVG text asks for; the PNG renderer maps it to DejaVu Sans.
const FONT: &str = "sans-serif";

/// Draws `spec` as a line chart with axes, tick labels, axis labels, a title and a legend.
/// The format follows the extension of `path`: `.svg` or `.png`.
pub fn plot_lines(path: impl AsRef<Path>, spec: &PlotSpec) -> Result<(), IoError> {
    let path = path.as_ref();
    let ext = extension(path);
    if ext != "svg" && ext != "png" {
        return Err(IoError::UnknownExtension { path: path.to_path_buf(), expected: ".svg or .png".into() });
    }
    let svg = render_svg(path, spec)?;
    if ext == "svg" {
        return write_atomic(path, |w| {
            use std::io::Write;
            w.write_all(svg.as_bytes()).map_err(|e| IoError::os(path, "cannot write", e))
        });
    }
    let (w, h) = spec.size;
    let rgb = rasterize(path, &svg, w, h)?;
    write_atomic(path, |wr| encode_png8(path, wr, h as usize, w as usize, 3, &rgb))
}

fn plot_err(path: &Path, e: impl std::fmt::Display) -> IoError {
    IoError::bad_input(path, format!("plot: {e}"))
}

/// Kept points of a series for the given axis kinds.
fn kept(points: &[(f64, f64)], log_x: bool, log_y: bool) -> Vec<(f64, f64)> {
    points.iter().copied().filter(|&(x, y)| x.is_finite() && y.is_finite() && (!log_x || x > 0.0) && (!log_y || y > 0.0)).collect()
}

/// Axis range covering `values` with a margin.
fn axis_range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return if log { (1.0, 10.0) } else { (0.0, 1.0) };
    }
    if log {
        if lo == hi {
            (lo / 2.0, hi * 2.0)
        } else {
            let f = (hi / lo).powf(0.05);
            (lo / f, hi * f)
        }
    } else if lo == hi {
        let d = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
        (lo - d, hi + d)
    } else {
        let d = (hi - lo) * 0.05;
        (lo - d, hi + d)
    }
}

fn render_svg(path: &Path, spec: &PlotSpec) -> Result<String, IoError> {
    if spec.size.0 < 100 || spec.size.1 < 100 {
        return Err(IoError::bad_input(path, format!("plot size {:?} is below 100x100", spec.size)));
    }
    let series: Vec<(&str, Vec<(f64, f64)>)> = spec.series.iter().map(|s| (s.name.as_str(), kept(&s.points, spec.log_x, spec.log_y))).collect();
    let (x0, x1) = axis_range(series.iter().flat_map(|s| s.1.iter().map(|p| p.0)), spec.log_x);
    let (y0, y1) = axis_range(series.iter().flat_map(|s| s.1.iter().map(|p| p.1)), spec.log_y);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, spec.size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
        let r = match (spec.log_x, spec.log_y) {
            (false, false) => draw(&root, spec, &series, x0..x1, y0..y1),
            (true, false) => draw(&root, spec, &series, (x0..x1).log_scale(), y0..y1),
            (false, true) => draw(&root, spec, &series, x0..x1, (y0..y1).log_scale()),
            (true, true) => draw(&root, spec, &series, (x0..x1).log_scale(), (y0..y1).log_scale()),
        };
        r.map_err(|e| plot_err(path, e))?;
        root.present().map_err(|e| plot_err(path, e))?;
    }
    Ok(svg)
}

type Area<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;

fn draw<XR, YR>(root: &Area<'_>, spec: &PlotSpec, series: &[(&str, Vec<(f64, f64)>)], xr: XR, yr: YR) -> Result<(), Box<dyn std::error::Error>>
where
    XR: AsRangedCoord<Value = f64>,
    YR: AsRangedCoord<Value = f64>,
    XR::CoordDescType: ValueFormatter<f64>,
    YR::CoordDescType: ValueFormatter<f64>,
{
    let mut chart =
        ChartBuilder::on(root).caption(&spec.title, (FONT, 24)).margin(16).x_label_area_size(50).y_label_area_size(80).build_cartesian_2d(xr, yr)?;
    chart
        .configure_mesh()
        .x_desc(&spec.x_label)
        .y_desc(&spec.y_label)
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 17))
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let [r, g, b] = SERIES_COLOURS[i % SERIES_COLOURS.len()];
        let colour = RGBColor(r, g, b);
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), colour.stroke_width(2)))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], colour.stroke_width(3)));
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled())))?;
    }
    if !series.is_empty() {
        chart
            .configure_series_labels()
            .position(legend_corner(series, spec.log_x, spec.log_y))
            .label_font((FONT, 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    Ok(())
}

/// Short tick text: `0.5`, `20`, `1500`, `1e5`, `2.5e-4`.
fn tick_label(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.2e}");
        // Drop trailing zeros of the mantissa: 1.00e5 -> 1e5, 2.50e-4 -> 2.5e-4.
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        let m = if m.contains('.') { m.trim_end_matches('0').trim_end_matches('.') } else { m };
        return format!("{m}e{e}");
    }
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.to_string()
    }
}

/// The plot corner whose neighbourhood holds the fewest data points, for the legend.
fn legend_corner(series: &[(&str, Vec<(f64, f64)>)], log_x: bool, log_y: bool) -> SeriesLabelPosition {
    let tx = |v: f64| if log_x { v.log10() } else { v };
    let ty = |v: f64| if log_y { v.log10() } else { v };
    let pts: Vec<(f64, f64)> = series.iter().flat_map(|s| s.1.iter().map(|&(x, y)| (tx(x), ty(y)))).collect();
    let (x0, x1) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (y0, y1) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let norm = |v: f64, lo: f64, hi: f64| if hi > lo { (v - lo) / (hi - lo) } else { 0.5 };
    let corners = [
        (SeriesLabelPosition::UpperRight, true, true),
        (SeriesLabelPosition::UpperLeft, false, true),
        (SeriesLabelPosition::LowerRight, true, false),
        (SeriesLabelPosition::LowerLeft, false, false),
    ];
    let mut best = (usize::MAX, SeriesLabelPosition::UpperRight);
    for (pos, right, upper) in corners {
        let n = pts
            .iter()
            .filter(|p| {
                let (u, v) = (norm(p.0, x0, x1), norm(p.1, y0, y1));
                (if right { u > 0.6 } else { u < 0.4 }) && (if upper { v > 0.7 } else { v < 0.3 })
            })
            .count();
        if n < best.0 {
            best = (n, pos);
        }
    }
    best.1
}

/// Font database holding the embedded DejaVu Sans as the sans-serif family.
fn fonts() -> Arc<usvg::fontdb::Database> {
    static DB: OnceLock<Arc<usvg::fontdb::Database>> = OnceLock::new();
    DB.get_or_init(|| {
        let mut db = usvg::fontdb::Database::new();
        db.load_font_data(dejavu::sans::regular().to_vec());
        db.set_sans_serif_family("DejaVu Sans");
        Arc::new(db)
    })
    .clone()
}

/// Renders SVG text to opaque 8-bit RGB pixels on white.
fn rasterize(path: &Path, svg: &str, w: u32, h: u32) -> Result<Vec<u8>, IoError> {
    let opt = usvg::Options { font_family: "DejaVu Sans".to_string(), fontdb: fonts(), ..usvg::Options::default() };
    let tree = usvg::Tree::from_str(svg, &opt).map_err(|e| plot_err(path, format!("SVG rendering: {e}")))?;
    let mut pixmap = tiny_skia::Pixmap::new(w, h).ok_or_else(|| plot_err(path, "cannot allocate the picture"))?;
    pixmap.fill(tiny_skia::Color::WHITE);
    let size = tree.size();
    let transform = tiny_skia::Transform::from_scale(w as f32 / size.width(), h as f32 / size.height());
    resvg::render(&tree, transform, &mut pixmap.as_mut());
    // Opaque background: premultiplied RGBA equals straight RGBA here.
    Ok(pixmap.data().chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_ranges_have_margins_and_survive_degenerate_input() {
        let (a, b) = axis_range([1.0, 3.0].into_iter(), false);
        assert!(a < 1.0 && b > 3.0);
        let (a, b) = axis_range([5.0].into_iter(), false);
        assert!(a < 5.0 && b > 5.0);
        let (a, b) = axis_range([10.0, 1000.0].into_iter(), true);
        assert!(a > 0.0 && a < 10.0 && b > 1000.0);
        assert_eq!(axis_range(std::iter::empty(), true), (1.0, 10.0));
        assert_eq!(kept(&[(0.0, 1.0), (1.0, f64::NAN), (2.0, 3.0)], true, false), vec![(2.0, 3.0)]);
    }

    #[test]
    fn tick_labels_are_short() {
        let cases = [(0.0, "0"), (0.5, "0.5"), (20.0, "20"), (1500.0, "1500"), (1e5, "1e5"), (2.5e-4, "2.5e-4"), (-3.25, "-3.25")];
        for (v, want) in cases {
            assert_eq!(tick_label(v), want, "{v}");
        }
    }

    #[test]
    fn legend_avoids_the_data() {
        // Rising curve: upper-left and lower-right corners are empty, upper-right is not.
        let rising = vec![("a", (0..50).map(|i| (i as f64, (i as f64).sqrt())).collect::<Vec<_>>())];
        let pos = legend_corner(&rising, false, false);
        assert!(matches!(pos, SeriesLabelPosition::UpperLeft | SeriesLabelPosition::LowerRight));
        // Falling curve on log axes: upper-right is free.
        let falling = vec![("b", (1..200).map(|i| (i as f64, 1.0 / (i as f64).powi(2))).collect::<Vec<_>>())];
        assert!(matches!(legend_corner(&falling, true, true), SeriesLabelPosition::UpperRight));
    }
}
