//! The paper's Fig. 5A for a flight: altitude, tilt angle, alpha and mean
//! normalized thrust against time, with the morphing, transition and
//! ground phases shaded, z_varphi and z* marked on the altitude panel and
//! the touchdown marked on every panel; the what-if overlay of a replay
//! (logged vs changed flight stack); and a Monte Carlo's touchdowns (tilt
//! against impact speed, one cloud per controller). PNG via plotters.

use std::path::Path;

use plotters::prelude::*;

use crate::error::{IoError, Result};
use crate::msg::Mode;

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

fn plot_err(e: impl std::fmt::Display) -> IoError {
    IoError::Output(format!("figure: {e}"))
}

/// The series labels of `chart` in the figures' one legend style.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(position)
        .draw()
        .map_err(plot_err)
}

impl FlightTrace {
    /// Adds the sample of one control tick: the height and tilt (the
    /// simulator's truth, or the flight stack's view for a real flight),
    /// and what the flight stack did (alpha counts in the air only).
    pub fn push(
        &mut self,
        time: f64,
        height: f64,
        tilt: f64,
        mode: Mode,
        alpha: f64,
        thrust: &[f64; 4],
    ) {
        let airborne = matches!(
            mode,
            Mode::Takeoff | Mode::Flight | Mode::Morphing | Mode::Transition | Mode::Failsafe
        );
        self.time.push(time);
        self.height.push(height);
        self.tilt_deg.push(tilt.to_degrees());
        self.alpha.push(if airborne { alpha } else { 0.0 });
        self.mean_thrust.push(thrust.iter().sum::<f64>() / 4.0);
        self.phase.push(match mode {
            Mode::Morphing => Phase::Morphing,
            Mode::Transition => Phase::Transition,
            Mode::Touchdown | Mode::Drive => Phase::Ground,
            _ => Phase::Air,
        });
    }
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
        return Err(IoError::Output(
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
            draw_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }
    }
    root.present().map_err(plot_err)?;
    Ok(())
}

/// One panel of a what-if overlay: the logged and the replayed series.
#[derive(Debug, Clone)]
pub struct OverlayPanel {
    pub label: &'static str,
    pub logged: Vec<f64>,
    pub replayed: Vec<f64>,
}

/// A what-if overlay: panels against a common time axis.
#[derive(Debug, Clone)]
pub struct Overlay {
    pub title: &'static str,
    pub time: Vec<f64>,
    pub panels: Vec<OverlayPanel>,
}

/// Writes `overlay` to `path` (PNG): one panel per series, logged in
/// blue, what-if in dashed red.
pub fn write_overlay_figure(path: &Path, overlay: &Overlay) -> Result<()> {
    if overlay.time.len() < 2 || overlay.panels.is_empty() {
        return Err(IoError::Output(
            "figure: fewer than two samples to plot".into(),
        ));
    }
    let t0 = overlay.time[0];
    let t1 = *overlay.time.last().unwrap_or(&t0);
    let rows = overlay.panels.len();
    let height = u32::try_from(rows).unwrap_or(4) * 300 + 60;
    let root = BitMapBackend::new(path, (1100, height)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let root = root
        .titled(overlay.title, ("sans-serif", 22))
        .map_err(plot_err)?;
    for (area, panel) in root.split_evenly((rows, 1)).iter().zip(&overlay.panels) {
        let finite = || {
            panel
                .logged
                .iter()
                .chain(&panel.replayed)
                .copied()
                .filter(|v| v.is_finite())
        };
        let lo = finite().fold(f64::INFINITY, f64::min);
        let hi = finite().fold(f64::NEG_INFINITY, f64::max);
        let (lo, hi) = if lo.is_finite() && hi > lo {
            let pad = 0.05 * (hi - lo);
            (lo - pad, hi + pad)
        } else if lo.is_finite() {
            (lo - 1.0, lo + 1.0)
        } else {
            (0.0, 1.0)
        };
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .x_label_area_size(34)
            .y_label_area_size(70)
            .build_cartesian_2d(t0..t1, lo..hi)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("time [s]")
            .y_desc(panel.label)
            .light_line_style(WHITE)
            .draw()
            .map_err(plot_err)?;
        let points = |values: &[f64]| -> Vec<(f64, f64)> {
            overlay
                .time
                .iter()
                .copied()
                .zip(values.iter().copied())
                .filter(|(_, v)| v.is_finite())
                .collect()
        };
        chart
            .draw_series(LineSeries::new(points(&panel.logged), BLUE.stroke_width(2)))
            .map_err(plot_err)?
            .label("logged")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], BLUE.stroke_width(2)));
        chart
            .draw_series(DashedLineSeries::new(
                points(&panel.replayed),
                6,
                4,
                RED.stroke_width(2),
            ))
            .map_err(plot_err)?
            .label("what-if")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], RED.stroke_width(2)));
        draw_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    }
    root.present().map_err(plot_err)?;
    Ok(())
}

/// One controller's touchdowns in a Monte Carlo: (tilt deg, impact m/s)
/// per run that touched down, and how many runs met the target criterion
/// (the caller's count: the criterion may ask more than the two numbers,
/// e.g. no crash).
#[derive(Debug, Clone)]
pub struct TouchdownCloud<'a> {
    pub label: &'a str,
    pub points: Vec<(f64, f64)>,
    pub in_target: usize,
}

/// Writes the touchdowns of a Monte Carlo to `path` (PNG): impact speed
/// against touchdown tilt, a cloud per controller on the same seeds, the
/// target region (tilt at least `tilt_min` deg, impact at most
/// `impact_max` m/s) shaded, and each cloud's count of runs in the target.
pub fn write_touchdown_figure(
    path: &Path,
    clouds: &[TouchdownCloud<'_>],
    tilt_min: f64,
    impact_max: f64,
    title: &str,
) -> Result<()> {
    let all = || clouds.iter().flat_map(|c| c.points.iter().copied());
    if all().next().is_none() {
        return Err(IoError::Output("figure: no touchdown to plot".into()));
    }
    let (t_lo, t_hi) = all().fold((tilt_min - 1.0, tilt_min + 1.0), |(lo, hi), (t, _)| {
        (lo.min(t - 0.5), hi.max(t + 0.5))
    });
    let v_hi = all().fold(impact_max + 0.05, |hi, (_, v)| hi.max(v + 0.02));
    let root = BitMapBackend::new(path, (900, 640)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(48)
        .y_label_area_size(64)
        .build_cartesian_2d(t_lo..t_hi, 0.0..v_hi)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("touchdown tilt (deg)")
        .y_desc("impact speed (m/s)")
        .draw()
        .map_err(plot_err)?;
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(tilt_min, 0.0), (t_hi, impact_max)],
            GREEN.mix(0.12).filled(),
        )))
        .map_err(plot_err)?;
    let colours = [RED, BLUE, BLACK, MAGENTA, CYAN];
    for (i, cloud) in clouds.iter().enumerate() {
        let colour = colours[i % colours.len()];
        chart
            .draw_series(
                cloud
                    .points
                    .iter()
                    .map(|&(t, v)| Circle::new((t, v), 3, colour.mix(0.7).filled())),
            )
            .map_err(plot_err)?
            .label(format!(
                "{}: {}/{} in the target",
                cloud.label,
                cloud.in_target,
                cloud.points.len()
            ))
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, colour.filled()));
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    root.present().map_err(plot_err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_touchdown_figure_is_a_png_and_refuses_an_empty_monte_carlo() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("touchdown.png");
        let clouds = [
            TouchdownCloud {
                label: "nominal",
                points: vec![(62.5, 0.35), (62.9, 0.31)],
                in_target: 0,
            },
            TouchdownCloud {
                label: "planned-tilt",
                points: vec![(65.4, 0.30), (63.2, 0.22), (66.1, 0.44)],
                in_target: 1,
            },
        ];
        write_touchdown_figure(&path, &clouds, 64.0, 0.4, "test").unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(b"\x89PNG"), "not a PNG");

        let empty = [TouchdownCloud {
            label: "crashed",
            points: Vec::new(),
            in_target: 0,
        }];
        let err = write_touchdown_figure(&dir.path().join("e.png"), &empty, 64.0, 0.4, "e");
        assert!(err.unwrap_err().to_string().contains("no touchdown"));
    }
}
