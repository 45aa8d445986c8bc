//! PNG plots of `rig identify` (plotters, bitmap backend, the DejaVu Sans font built in):
//! measured against the model before and after, and the residual with its correlations.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::FontStyle;
use rig_model::identify::Identified;

static FONT: Once = Once::new();

fn register_font() {
    FONT.call_once(|| {
        // Failure only loses the labels; the curves are still drawn.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            include_bytes!("../assets/DejaVuSans.ttf"),
        );
    });
}

const MEASURED: RGBColor = RGBColor(90, 90, 90);
const BEFORE: RGBColor = RGBColor(40, 110, 200);
const AFTER: RGBColor = RGBColor(220, 60, 40);

/// Contiguous stretches (split where time jumps back or by over 5 median steps), each
/// thinned to about `max_points` in all.
fn stretches(t: &[f64], dt: f64, max_points: usize) -> Vec<Vec<usize>> {
    let stride = (t.len() / max_points.max(1)).max(1);
    let mut out: Vec<Vec<usize>> = vec![vec![]];
    for i in 0..t.len() {
        if i > 0 && (t[i] < t[i - 1] || t[i] - t[i - 1] > 5.0 * dt.max(1e-9)) {
            out.push(vec![]);
        }
        if i % stride == 0
            && let Some(last) = out.last_mut()
        {
            last.push(i);
        }
    }
    out.retain(|s| s.len() > 1);
    out
}

fn range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = vals
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    (lo - pad, hi + pad)
}

type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn msg<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// A captioned chart with a mesh and axis labels.
fn chart<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    caption: &str,
    x: (f64, f64),
    y: (f64, f64),
    x_desc: &str,
    y_desc: &str,
) -> Result<Chart<'a, 'b>, String> {
    let mut c = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(msg)?;
    c.configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .draw()
        .map_err(msg)?;
    Ok(c)
}

/// Lines through the contiguous stretches of `t`, one legend entry for all.
fn stretch_lines(
    c: &mut Chart<'_, '_>,
    t: &[f64],
    dt: f64,
    label: &str,
    style: ShapeStyle,
    point: impl Fn(usize) -> (f64, f64),
) -> Result<(), String> {
    let mut first = true;
    for s in stretches(t, dt, 4000) {
        let a = c
            .draw_series(LineSeries::new(s.iter().map(|&k| point(k)), style))
            .map_err(msg)?;
        if first && !label.is_empty() {
            let color = style.color;
            a.label(label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
            });
            first = false;
        }
    }
    Ok(())
}

fn legend<'a, 'b: 'a>(c: &mut Chart<'a, 'b>) -> Result<(), String> {
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(msg)
}

/// The first held-out run only (so time runs forward), as row indices.
fn first_run(res: &Identified) -> Vec<usize> {
    let first = res.heldout.run.first().copied().unwrap_or(0);
    (0..res.heldout.run.len())
        .filter(|&i| res.heldout.run[i] == first)
        .collect()
}

/// Measured torque against the model before and after: over time, and against the angle.
pub fn fit(path: &Path, res: &Identified) -> Result<(), String> {
    draw_fit(path, res).map_err(|e| format!("cannot draw {}: {e}", path.display()))
}

fn draw_fit(path: &Path, res: &Identified) -> Result<(), String> {
    register_font();
    let h = &res.heldout;
    let rows = first_run(res);
    let t: Vec<f64> = rows.iter().map(|&i| h.t[i]).collect();
    let root = BitMapBackend::new(path, (1200, 1000)).into_drawing_area();
    root.fill(&WHITE).map_err(msg)?;
    let (top, bottom) = root.split_vertically(480);
    let series = [
        ("measured", MEASURED, &h.measured, 2),
        ("before", BEFORE, &h.before, 1),
        ("after", AFTER, &h.after, 1),
    ];
    let y = range(rows.iter().map(|&i| h.measured[i]));
    let caption = format!(
        "held-out torque, model {}: RMSE {:.4} → {:.4} N·m",
        res.model.name(),
        res.before.rmse,
        res.after.rmse
    );
    let tr = range(t.iter().copied());
    let mut c = chart(&top, &caption, tr, y, "time in run [s]", "torque [N·m]")?;
    for (name, color, ys, w) in series {
        stretch_lines(&mut c, &t, res.dt, name, color.stroke_width(w), |k| {
            (t[k], ys[rows[k]])
        })?;
    }
    legend(&mut c)?;
    let x_desc = if res.model.name() == "link" {
        "link angle q [rad]"
    } else {
        "deflection φ [rad]"
    };
    let xr = range(rows.iter().map(|&i| h.x[i]));
    let mut c = chart(
        &bottom,
        "torque against angle (the loop)",
        xr,
        y,
        x_desc,
        "torque [N·m]",
    )?;
    for (_, color, ys, _) in series {
        stretch_lines(&mut c, &t, res.dt, "", color.stroke_width(1), |k| {
            (h.x[rows[k]], ys[rows[k]])
        })?;
    }
    root.present().map_err(msg)
}

/// The held-out residual before and after, its autocorrelation and its cross-correlations.
pub fn residual(path: &Path, res: &Identified) -> Result<(), String> {
    draw_residual(path, res).map_err(|e| format!("cannot draw {}: {e}", path.display()))
}

fn draw_residual(path: &Path, res: &Identified) -> Result<(), String> {
    register_font();
    let h = &res.heldout;
    let rows = first_run(res);
    let t: Vec<f64> = rows.iter().map(|&i| h.t[i]).collect();
    let e_before: Vec<f64> = rows.iter().map(|&i| h.measured[i] - h.before[i]).collect();
    let e_after: Vec<f64> = rows.iter().map(|&i| h.measured[i] - h.after[i]).collect();
    let root = BitMapBackend::new(path, (1200, 1200)).into_drawing_area();
    root.fill(&WHITE).map_err(msg)?;
    let parts = root.split_evenly((3, 1));
    let y = range(e_before.iter().chain(&e_after).copied());
    let mut c = chart(
        &parts[0],
        "held-out residual (measured − model)",
        range(t.iter().copied()),
        y,
        "time in run [s]",
        "residual [N·m]",
    )?;
    for (name, color, e) in [("before", BEFORE, &e_before), ("after", AFTER, &e_after)] {
        stretch_lines(&mut c, &t, res.dt, name, color.stroke_width(1), |k| {
            (t[k], e[k])
        })?;
    }
    legend(&mut c)?;

    let r = &res.residual;
    let lag_max = r.lags as f64 * res.dt;
    let caption = format!(
        "autocorrelation after (band ±{:.3}: {})",
        r.band,
        if r.white { "white" } else { "not white" }
    );
    let mut c = chart(
        &parts[1],
        &caption,
        (0.0, lag_max),
        (-1.0, 1.0),
        "lag [s]",
        "ρ",
    )?;
    c.draw_series(r.autocorr.iter().enumerate().map(|(k, v)| {
        let x = (k + 1) as f64 * res.dt;
        PathElement::new(vec![(x, 0.0), (x, *v)], AFTER.stroke_width(2))
    }))
    .map_err(msg)?;
    for b in [r.band, -r.band] {
        c.draw_series(LineSeries::new(vec![(0.0, b), (lag_max, b)], BLACK))
            .map_err(msg)?;
    }

    let span = r
        .cross_curves
        .first()
        .and_then(|(_, c)| c.last().map(|p| p.0))
        .unwrap_or(1.0)
        .max(1e-6);
    let mut c = chart(
        &parts[2],
        "cross-correlation of the residual with the inputs",
        (-span, span),
        (-1.0, 1.0),
        "lag [s] (positive: the residual follows the input)",
        "ρ",
    )?;
    let colors = [BLUE, RGBColor(0, 150, 80), MAGENTA];
    for ((name, curve), color) in r.cross_curves.iter().zip(colors) {
        let lag: Vec<f64> = curve.iter().map(|p| p.0).collect();
        stretch_lines(&mut c, &lag, 1.0, name, color.stroke_width(2), |k| curve[k])?;
    }
    legend(&mut c)?;
    root.present().map_err(msg)
}
