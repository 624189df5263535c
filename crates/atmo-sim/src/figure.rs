//! The paper's Fig. 5A for a simulated flight: altitude, tilt angle, alpha
//! and mean normalized thrust against time, with the morphing, transition
//! and ground phases shaded, z_varphi and z* marked on the altitude panel
//! and the touchdown marked on every panel. PNG via plotters.

use std::path::Path;

use plotters::prelude::*;

use crate::error::{Result, SimError};

/// Which phase of the landing a sample belongs to (for shading).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    Air,
    Morphing,
    Transition,
    Ground,
}

/// One flight, sampled at the control rate.
#[derive(Debug, Clone, Default)]
pub struct FlightTrace {
    pub time: Vec<f64>,
    /// Height of the base origin above the ground, m.
    pub height: Vec<f64>,
    pub tilt_deg: Vec<f64>,
    pub alpha: Vec<f64>,
    /// Mean of the four normalized thruster commands.
    pub mean_thrust: Vec<f64>,
    pub phase: Vec<Phase>,
}

/// Lines drawn across the altitude panel and the touchdown marker.
#[derive(Debug, Clone, Copy)]
pub struct Markers {
    /// z_varphi, m.
    pub morph_height: f64,
    /// z*, m.
    pub transition_height: f64,
    /// Time of first wheel contact, s.
    pub touchdown: Option<f64>,
}

fn plot_err(e: impl std::fmt::Display) -> SimError {
    SimError::Output(format!("figure: {e}"))
}

/// Spans `[t0, t1)` of consecutive samples in `phase`.
fn spans(trace: &FlightTrace, phase: Phase) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, p) in trace.phase.iter().enumerate() {
        match (start, *p == phase) {
            (None, true) => start = Some(trace.time[i]),
            (Some(s), false) => {
                out.push((s, trace.time[i]));
                start = None;
            }
            _ => {}
        }
    }
    if let (Some(s), Some(&end)) = (start, trace.time.last()) {
        out.push((s, end));
    }
    out
}

/// Writes the figure to `path` (PNG).
pub fn write_landing_figure(
    path: &Path,
    trace: &FlightTrace,
    markers: &Markers,
    title: &str,
) -> Result<()> {
    if trace.time.len() < 2 {
        return Err(SimError::Output(
            "figure: fewer than two samples to plot".into(),
        ));
    }
    let t0 = trace.time[0];
    let t1 = *trace.time.last().unwrap_or(&t0);
    let root = BitMapBackend::new(path, (1100, 1300)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let root = root.titled(title, ("sans-serif", 26)).map_err(plot_err)?;
    let panels = root.split_evenly((4, 1));
    let max_height = trace
        .height
        .iter()
        .copied()
        .fold(markers.morph_height, f64::max)
        * 1.1;
    let max_thrust = trace.mean_thrust.iter().copied().fold(1.0, f64::max);
    let series: [(&str, &Vec<f64>, f64, f64, RGBColor); 4] = [
        ("altitude [m]", &trace.height, 0.0, max_height, BLUE),
        (
            "tilt angle varphi [deg]",
            &trace.tilt_deg,
            0.0,
            90.0,
            RGBColor(200, 80, 0),
        ),
        (
            "alpha = f(z) cos varphi",
            &trace.alpha,
            0.0,
            1.05,
            RGBColor(0, 130, 60),
        ),
        (
            "mean thrust (normalized)",
            &trace.mean_thrust,
            0.0,
            max_thrust * 1.05,
            RGBColor(120, 0, 160),
        ),
    ];
    let shades = [
        (Phase::Morphing, RGBColor(255, 200, 120)),
        (Phase::Transition, RGBColor(255, 140, 140)),
        (Phase::Ground, RGBColor(170, 170, 170)),
    ];
    for (panel, (label, values, lo, hi, color)) in panels.iter().zip(series) {
        let mut chart = ChartBuilder::on(panel)
            .margin(8)
            .x_label_area_size(34)
            .y_label_area_size(70)
            .build_cartesian_2d(t0..t1, lo..hi)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("time [s]")
            .y_desc(label)
            .light_line_style(WHITE)
            .draw()
            .map_err(plot_err)?;
        for (phase, shade) in shades {
            let name = match phase {
                Phase::Morphing => "morphing",
                Phase::Transition => "transition",
                _ => "ground",
            };
            let mut first = true;
            for (a, b) in spans(trace, phase) {
                let drawn = chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(a, lo), (b, hi)],
                        shade.mix(0.35).filled(),
                    )))
                    .map_err(plot_err)?;
                if first && label.starts_with("altitude") {
                    drawn.label(name).legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 16, y + 5)], shade.mix(0.6).filled())
                    });
                }
                first = false;
            }
        }
        chart
            .draw_series(LineSeries::new(
                trace.time.iter().copied().zip(values.iter().copied()),
                color.stroke_width(2),
            ))
            .map_err(plot_err)?;
        if label.starts_with("altitude") {
            for (h, name, c) in [
                (markers.morph_height, "z_varphi", RGBColor(200, 120, 0)),
                (markers.transition_height, "z*", RED),
            ] {
                chart
                    .draw_series(DashedLineSeries::new(
                        [(t0, h), (t1, h)],
                        8,
                        6,
                        c.stroke_width(2),
                    ))
                    .map_err(plot_err)?
                    .label(format!("{name} = {h:.2} m"))
                    .legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 16, y)], c.stroke_width(2))
                    });
            }
        }
        if label.starts_with("tilt") {
            for (deg, c) in [(50.0, RGBColor(90, 90, 90)), (70.0, RED)] {
                chart
                    .draw_series(DashedLineSeries::new(
                        [(t0, deg), (t1, deg)],
                        4,
                        6,
                        c.stroke_width(1),
                    ))
                    .map_err(plot_err)?;
            }
        }
        if let Some(td) = markers.touchdown {
            let drawn = chart
                .draw_series(std::iter::once(PathElement::new(
                    [(td, lo), (td, hi)],
                    BLACK.stroke_width(2),
                )))
                .map_err(plot_err)?;
            if label.starts_with("altitude") {
                drawn
                    .label(format!("touchdown t = {td:.2} s"))
                    .legend(|(x, y)| {
                        PathElement::new([(x, y), (x + 16, y)], BLACK.stroke_width(2))
                    });
            }
        }
        if label.starts_with("altitude") {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(plot_err)?;
        }
    }
    root.present().map_err(plot_err)?;
    Ok(())
}
