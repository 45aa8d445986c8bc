//! PNG plots of `rig identify` (plotters, bitmap backend, the DejaVu Sans font built in):
//! measured against the model before and after, and the residual with its correlations.

use std::path::Path;
use std::sync::Once;

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

fn err<E: std::fmt::Display>(path: &Path) -> impl Fn(E) -> String + '_ {
    move |e| format!("cannot draw {}: {e}", path.display())
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
    register_font();
    let h = &res.heldout;
    let rows = first_run(res);
    let t: Vec<f64> = rows.iter().map(|&i| h.t[i]).collect();
    let root = BitMapBackend::new(path, (1200, 1000)).into_drawing_area();
    root.fill(&WHITE).map_err(err(path))?;
    let (top, bottom) = root.split_vertically(480);
    let series = [
        ("measured", MEASURED, &h.measured),
        ("before", BEFORE, &h.before),
        ("after", AFTER, &h.after),
    ];
    let (t0, t1) = range(t.iter().copied());
    let (y0, y1) = range(rows.iter().map(|&i| h.measured[i]));
    let mut c = ChartBuilder::on(&top)
        .caption(
            format!(
                "held-out torque, model {}: RMSE {:.4} → {:.4} N·m",
                res.model.name(),
                res.before.rmse,
                res.after.rmse
            ),
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(t0..t1, y0..y1)
        .map_err(err(path))?;
    c.configure_mesh()
        .x_desc("time in run [s]")
        .y_desc("torque [N·m]")
        .draw()
        .map_err(err(path))?;
    for (name, color, ys) in series {
        let mut first = true;
        for s in stretches(&t, res.dt, 4000) {
            let a = c
                .draw_series(LineSeries::new(
                    s.iter().map(|&k| (t[k], ys[rows[k]])),
                    color.stroke_width(if name == "measured" { 2 } else { 1 }),
                ))
                .map_err(err(path))?;
            if first {
                a.label(name).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
                });
                first = false;
            }
        }
    }
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err(path))?;

    let (x0, x1) = range(rows.iter().map(|&i| h.x[i]));
    let mut c = ChartBuilder::on(&bottom)
        .caption("torque against angle (the loop)", ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err(path))?;
    c.configure_mesh()
        .x_desc(if res.model.name() == "link" {
            "link angle q [rad]"
        } else {
            "deflection φ [rad]"
        })
        .y_desc("torque [N·m]")
        .draw()
        .map_err(err(path))?;
    for (_, color, ys) in series {
        for s in stretches(&t, res.dt, 4000) {
            c.draw_series(LineSeries::new(
                s.iter().map(|&k| (h.x[rows[k]], ys[rows[k]])),
                color.stroke_width(1),
            ))
            .map_err(err(path))?;
        }
    }
    root.present().map_err(err(path))?;
    Ok(())
}

/// The held-out residual before and after, its autocorrelation and its cross-correlations.
pub fn residual(path: &Path, res: &Identified) -> Result<(), String> {
    register_font();
    let h = &res.heldout;
    let rows = first_run(res);
    let t: Vec<f64> = rows.iter().map(|&i| h.t[i]).collect();
    let e_before: Vec<f64> = rows.iter().map(|&i| h.measured[i] - h.before[i]).collect();
    let e_after: Vec<f64> = rows.iter().map(|&i| h.measured[i] - h.after[i]).collect();
    let root = BitMapBackend::new(path, (1200, 1200)).into_drawing_area();
    root.fill(&WHITE).map_err(err(path))?;
    let parts = root.split_evenly((3, 1));
    let (t0, t1) = range(t.iter().copied());
    let (y0, y1) = range(e_before.iter().chain(&e_after).copied());
    let mut c = ChartBuilder::on(&parts[0])
        .caption("held-out residual (measured − model)", ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(t0..t1, y0..y1)
        .map_err(err(path))?;
    c.configure_mesh()
        .x_desc("time in run [s]")
        .y_desc("residual [N·m]")
        .draw()
        .map_err(err(path))?;
    for (name, color, e) in [("before", BEFORE, &e_before), ("after", AFTER, &e_after)] {
        let mut first = true;
        for s in stretches(&t, res.dt, 4000) {
            let a = c
                .draw_series(LineSeries::new(s.iter().map(|&k| (t[k], e[k])), color))
                .map_err(err(path))?;
            if first {
                a.label(name).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
                });
                first = false;
            }
        }
    }
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err(path))?;

    let r = &res.residual;
    let lag_max = r.lags as f64 * res.dt;
    let mut c = ChartBuilder::on(&parts[1])
        .caption(
            format!(
                "autocorrelation after (band ±{:.3}: {})",
                r.band,
                if r.white { "white" } else { "not white" }
            ),
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..lag_max, -1.0..1.0)
        .map_err(err(path))?;
    c.configure_mesh()
        .x_desc("lag [s]")
        .y_desc("ρ")
        .draw()
        .map_err(err(path))?;
    c.draw_series(r.autocorr.iter().enumerate().map(|(k, v)| {
        let x = (k + 1) as f64 * res.dt;
        PathElement::new(vec![(x, 0.0), (x, *v)], AFTER.stroke_width(2))
    }))
    .map_err(err(path))?;
    for b in [r.band, -r.band] {
        c.draw_series(LineSeries::new(vec![(0.0, b), (lag_max, b)], BLACK))
            .map_err(err(path))?;
    }

    let span = r
        .cross_curves
        .first()
        .and_then(|(_, c)| c.last().map(|p| p.0))
        .unwrap_or(1.0)
        .max(1e-6);
    let mut c = ChartBuilder::on(&parts[2])
        .caption(
            "cross-correlation of the residual with the inputs",
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(-span..span, -1.0..1.0)
        .map_err(err(path))?;
    c.configure_mesh()
        .x_desc("lag [s] (positive: the residual follows the input)")
        .y_desc("ρ")
        .draw()
        .map_err(err(path))?;
    let colors = [BLUE, RGBColor(0, 150, 80), MAGENTA];
    for ((name, curve), color) in r.cross_curves.iter().zip(colors) {
        c.draw_series(LineSeries::new(
            curve.iter().copied(),
            color.stroke_width(2),
        ))
        .map_err(err(path))?
        .label(*name)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3)));
    }
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err(path))?;
    root.present().map_err(err(path))?;
    Ok(())
}
