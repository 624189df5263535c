//! The success map of a landing campaign: one panel per quantity over a
//! grid of two swept parameters (the wheel-landing target's rate with its
//! Wilson interval, the median touchdown tilt, the median impact speed).

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::error::{IoError, Result};

/// One cell of the grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapCell {
    /// Runs at the target, of `runs`, and the rate's Wilson 95 % interval.
    pub in_target: usize,
    pub runs: usize,
    pub wilson_95: [f64; 2],
    /// Medians over the runs that touched down (none: no touchdown).
    pub touchdown_tilt_deg: Option<f64>,
    pub impact_speed_mps: Option<f64>,
}

/// A swept parameter as an axis: its label and grid values.
#[derive(Debug, Clone, Copy)]
pub struct MapAxis<'a> {
    pub label: &'a str,
    pub values: &'a [f64],
}

/// A panel: its caption, and each cell's colour value (0 bad, 1 good) and
/// text (lines split at `|`).
type Panel<'p> = (&'p str, Box<dyn Fn(&MapCell) -> (f64, String) + 'p>);

fn plot_err(e: impl std::fmt::Display) -> IoError {
    IoError::Output(format!("success map: {e}"))
}

/// The grid value under the axis position `v` when `v` is a cell's centre
/// (the axis is in cell units), else nothing.
fn cell_label(values: &[f64], v: f64) -> String {
    let i = v.floor() as usize;
    let centre = (v - i as f64 - 0.5).abs() < 1e-9;
    values
        .get(i)
        .filter(|_| centre)
        .map_or(String::new(), ToString::to_string)
}

/// Red (0) through yellow to green (1).
fn rate_colour(t: f64) -> RGBColor {
    let t = t.clamp(0.0, 1.0);
    let (r, g) = if t < 0.5 {
        (230.0, 60.0 + 2.0 * t * 170.0)
    } else {
        (
            230.0 - 2.0 * (t - 0.5) * 190.0,
            230.0 - 2.0 * (t - 0.5) * 50.0,
        )
    };
    RGBColor(r as u8, g as u8, 70)
}

/// Writes the map: `cells[ix * y.values.len() + iy]` is the cell at
/// `x.values[ix]`, `y.values[iy]` (the last parameter varying fastest).
/// A one-parameter sweep passes a `y` with one value.
///
/// # Errors
/// A grid whose size does not match the cells, or a drawing or file error.
pub fn write_success_map(
    path: &Path,
    title: &str,
    x: MapAxis<'_>,
    y: MapAxis<'_>,
    cells: &[MapCell],
    tilt_min_deg: f64,
    impact_max_mps: f64,
) -> Result<()> {
    let (nx, ny) = (x.values.len(), y.values.len());
    if nx == 0 || ny == 0 || nx * ny != cells.len() {
        return Err(plot_err(format!(
            "{} cells for a {nx} x {ny} grid",
            cells.len()
        )));
    }
    let root = BitMapBackend::new(path, (1500, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let root = root.titled(title, ("sans-serif", 24)).map_err(plot_err)?;
    let panels = root.split_evenly((1, 3));
    let range = |k: fn(&MapCell) -> Option<f64>| {
        cells
            .iter()
            .filter_map(k)
            .fold(None, |acc: Option<(f64, f64)>, v| {
                Some(acc.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))))
            })
    };
    let tilt_range = range(|c| c.touchdown_tilt_deg);
    let impact_range = range(|c| c.impact_speed_mps);
    // Colour: 1 is good. The tilt is good at and above its minimum, the
    // impact at and below its maximum; both ramps span the grid's values
    // and the criterion.
    let ramp = |v: f64, good_high: bool, (lo, hi): (f64, f64), threshold: f64| {
        let (lo, hi) = (lo.min(threshold), hi.max(threshold));
        let t = if hi > lo { (v - lo) / (hi - lo) } else { 1.0 };
        if good_high { t } else { 1.0 - t }
    };
    let specs: [Panel<'_>; 3] = [
        (
            "at the target (Wilson 95 %)",
            Box::new(|c: &MapCell| {
                let rate = if c.runs == 0 {
                    0.0
                } else {
                    c.in_target as f64 / c.runs as f64
                };
                (
                    rate,
                    format!(
                        "{}/{}|{:.0}-{:.0} %",
                        c.in_target,
                        c.runs,
                        100.0 * c.wilson_95[0],
                        100.0 * c.wilson_95[1]
                    ),
                )
            }),
        ),
        (
            "median touchdown tilt (deg)",
            Box::new(
                move |c: &MapCell| match (c.touchdown_tilt_deg, tilt_range) {
                    (Some(v), Some(r)) => (ramp(v, true, r, tilt_min_deg), format!("{v:.1}")),
                    _ => (0.0, "-".to_string()),
                },
            ),
        ),
        (
            "median impact speed (m/s)",
            Box::new(
                move |c: &MapCell| match (c.impact_speed_mps, impact_range) {
                    (Some(v), Some(r)) => (ramp(v, false, r, impact_max_mps), format!("{v:.2}")),
                    _ => (0.0, "-".to_string()),
                },
            ),
        ),
    ];
    for (panel, (name, value)) in panels.iter().zip(specs.iter()) {
        let mut chart = ChartBuilder::on(panel)
            .caption(*name, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(50)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..nx as f64, 0.0..ny as f64)
            .map_err(plot_err)?;
        let x_label = |v: &f64| cell_label(x.values, *v);
        let y_label = |v: &f64| cell_label(y.values, *v);
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(x.label)
            .y_desc(y.label)
            .x_labels(2 * nx + 1)
            .y_labels(2 * ny + 1)
            .x_label_formatter(&x_label)
            .y_label_formatter(&y_label)
            .draw()
            .map_err(plot_err)?;
        for ix in 0..nx {
            for iy in 0..ny {
                let c = &cells[ix * ny + iy];
                let (t, text) = value(c);
                let (x0, y0) = (ix as f64, iy as f64);
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(x0, y0), (x0 + 1.0, y0 + 1.0)],
                        rate_colour(t).filled(),
                    )))
                    .map_err(plot_err)?;
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(x0, y0), (x0 + 1.0, y0 + 1.0)],
                        WHITE.stroke_width(1),
                    )))
                    .map_err(plot_err)?;
                let lines: Vec<&str> = text.split('|').collect();
                let n = lines.len() as f64;
                for (k, line) in lines.iter().enumerate() {
                    let yy = y0 + 0.5 + 0.12 * ((n - 1.0) / 2.0 - k as f64);
                    chart
                        .draw_series(std::iter::once(Text::new(
                            (*line).to_string(),
                            (x0 + 0.5, yy),
                            ("sans-serif", 13)
                                .into_font()
                                .color(&BLACK)
                                .pos(Pos::new(HPos::Center, VPos::Center)),
                        )))
                        .map_err(plot_err)?;
                }
            }
        }
    }
    root.present().map_err(plot_err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_that_does_not_match_its_cells_is_refused() {
        let cell = MapCell {
            in_target: 1,
            runs: 2,
            wilson_95: [0.1, 0.9],
            touchdown_tilt_deg: Some(65.0),
            impact_speed_mps: Some(0.3),
        };
        let dir = std::env::temp_dir().join(format!("atmo-map-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let axis = MapAxis {
            label: "a",
            values: &[1.0, 2.0],
        };
        let err = write_success_map(&dir.join("m.png"), "t", axis, axis, &[cell; 3], 64.0, 0.4)
            .unwrap_err()
            .to_string();
        assert!(err.contains("3 cells for a 2 x 2 grid"), "{err}");
        write_success_map(&dir.join("m.png"), "t", axis, axis, &[cell; 4], 64.0, 0.4).unwrap();
        assert!(std::fs::metadata(dir.join("m.png")).unwrap().len() > 1000);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
