//! SVG plots (plotters, SVG backend only, so no font libraries are needed): a simulation's
//! trajectory, |C| and energy error over time; a work-precision chart for `bench`.
//!
//! Every function returns the SVG text; the caller writes it.

use crate::numeric::simulate::Summary;
use plotters::coord::Shift;
use plotters::prelude::*;

/// Colours for successive series.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// The floor for log axes: values at or below it are drawn at it.
const LOG_FLOOR: f64 = 1e-18;

fn err<E: std::fmt::Display>(e: E) -> String {
    format!("cannot draw the plot: {e}")
}

/// (min, max) of `xs`, widened when empty or flat.
fn range(xs: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) =
        xs.filter(|x| x.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
    if lo > hi {
        return (0.0, 1.0);
    }
    let pad = 0.05 * (hi - lo).max(hi.abs().max(lo.abs()) * 1e-9).max(f64::MIN_POSITIVE);
    (lo - pad, hi + pad)
}

/// (min, max) for a log axis.
fn log_range(xs: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = xs
        .filter(|x| x.is_finite())
        .map(|x| x.max(LOG_FLOOR))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
    if lo > hi {
        return (LOG_FLOOR, 1.0);
    }
    // At most 30 decades: a log axis over hundreds (|C| ≈ 1e296 of a 1e155 m pendulum next
    // to the floor) shows nothing more, and plotters' tick generation then takes minutes.
    let lo = lo.max(hi * 1e-30);
    (lo / 2.0, (hi * 2.0).max(lo * 10.0))
}

/// Three panels: the trajectory (first two coordinates of up to 8 bodies), max |C| and
/// |energy error| against time.
pub fn simulation(title: &str, summary: &Summary) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1200, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(title, ("sans-serif", 20)).map_err(err)?;
        let panels = root.split_evenly((1, 3));
        trajectory(&panels[0], summary)?;
        let c = summary.samples.iter().map(|s| (s.time, s.max_abs_c));
        over_time(&panels[1], "max |C/κ|", c)?;
        let e = summary.samples.iter().map(|s| (s.time, s.energy_error.abs()));
        over_time(&panels[2], "|energy balance| (T − T₀ − W)", e)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
}

fn trajectory(area: &DrawingArea<SVGBackend, Shift>, summary: &Summary) -> Result<(), String> {
    let all = || summary.samples.iter().flat_map(|s| s.position.iter());
    let (x0, x1) = range(all().map(|p| p[0]));
    let (y0, y1) = range(all().map(|p| p[1]));
    let mut chart = ChartBuilder::on(area)
        .caption("trajectory", ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    chart.configure_mesh().x_desc("x").y_desc("y").draw().map_err(err)?;
    let bodies = summary.samples.first().map_or(0, |s| s.position.len());
    for b in 0..bodies {
        let points = summary.samples.iter().map(|s| (s.position[b][0], s.position[b][1]));
        chart.draw_series(LineSeries::new(points, PALETTE[b % PALETTE.len()])).map_err(err)?;
    }
    Ok(())
}

fn over_time(
    area: &DrawingArea<SVGBackend, Shift>,
    what: &str,
    points: impl Iterator<Item = (f64, f64)> + Clone,
) -> Result<(), String> {
    let (t0, t1) = range(points.clone().map(|p| p.0));
    let (y0, y1) = log_range(points.clone().map(|p| p.1));
    let mut chart = ChartBuilder::on(area)
        .caption(what, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(t0..t1, (y0..y1).log_scale())
        .map_err(err)?;
    chart.configure_mesh().x_desc("t").y_label_formatter(&|y| format!("{y:.0e}")).draw().map_err(err)?;
    chart.draw_series(LineSeries::new(points.map(|(t, y)| (t, y.max(LOG_FLOOR))), PALETTE[0])).map_err(err)?;
    Ok(())
}

/// One line of a work-precision chart: a method's (cost, error) points.
pub struct Line {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// Error against cost on log-log axes, one line per method.
pub fn work_precision(title: &str, x_label: &str, y_label: &str, lines: &[Line]) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 600)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let all = || lines.iter().flat_map(|l| l.points.iter());
        let (x0, x1) = log_range(all().map(|p| p.0));
        let (y0, y1) = log_range(all().map(|p| p.1));
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .x_label_formatter(&|x| format!("{x:.0e}"))
            .y_label_formatter(&|y| format!("{y:.0e}"))
            .draw()
            .map_err(err)?;
        for (i, line) in lines.iter().enumerate() {
            let colour = PALETTE[i % PALETTE.len()];
            let style = if i < PALETTE.len() { colour.stroke_width(2) } else { colour.stroke_width(1) };
            let points: Vec<(f64, f64)> =
                line.points.iter().map(|&(x, y)| (x.max(LOG_FLOOR), y.max(LOG_FLOOR))).collect();
            chart
                .draw_series(LineSeries::new(points.clone(), style))
                .map_err(err)?
                .label(line.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
            chart.draw_series(points.into_iter().map(|p| Circle::new(p, 3, colour.filled()))).map_err(err)?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
}
