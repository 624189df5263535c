//! Outputs: `report.md`, `fitted_effects.toml`, `explain.json` and PNG
//! plots (residual heat maps before and after, time series of recording vs
//! model before and after, effect scores).

use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;
use serde_json::json;

use crate::data::{CHANNEL_UNITS, CHANNELS};
use crate::effects::{self, Effect};
use crate::regions::{HEIGHT_EDGES, Location, VARPHI_EDGES};
use crate::{ExplainError, Explanation, HIGH_CONFIDENCE};

fn out_err(e: impl std::fmt::Display) -> ExplainError {
    ExplainError::Output(e.to_string())
}

/// The JSON document (`explain.json`).
pub fn json(ex: &Explanation) -> serde_json::Value {
    let effects: Vec<serde_json::Value> = ex
        .effects
        .iter()
        .map(|e| {
            json!({
                "name": e.name,
                "physics": e.physics,
                "selected": e.selected,
                "confidence": e.confidence,
                "high_confidence": e.selected && e.confidence.is_some_and(|c| c >= HIGH_CONFIDENCE),
                "selection_frequency": e.selection_frequency,
                "decision": e.decision,
                "heldout_gain": e.heldout_gain,
                "parameters": e.parameters,
                "indistinguishable_from": e.indistinguishable_from,
                "same_finding_as": e.same_finding_as,
                "combined": e.combined,
                "decided_by": e.decided_by,
                "stage": if e.calibration { "calibration" } else { "physics" },
            })
        })
        .collect();
    let rms = |t: &crate::RmsTable| {
        json!({
            "per_channel": CHANNELS.iter().zip(t.per_channel).map(|(c, v)| (c.to_string(), json!(v))).collect::<serde_json::Map<String, serde_json::Value>>(),
            "located_region_per_channel": CHANNELS.iter().zip(t.located_per_channel).map(|(c, v)| (c.to_string(), json!(v))).collect::<serde_json::Map<String, serde_json::Value>>(),
            "located_region_normalized": t.located_normalized,
            "located_region_rows": t.located_rows,
        })
    };
    json!({
        "source": ex.source,
        "rows": ex.rows,
        "rows_used": ex.rows_used,
        "rate_hz": ex.rate_hz,
        "duration_s": ex.duration_s,
        "window_samples": ex.window_samples,
        "ignored_columns": ex.ignored_columns,
        "skipped_nonfinite_rows": ex.skipped_nonfinite,
        "skipped_time_rows": ex.skipped_time,
        "implausible_rows": ex.outliers.rows,
        "implausible_columns": ex.outliers.columns,
        "skipped_rotation_rows": ex.skipped_rotation,
        "jump_rows": ex.jumps.rows,
        "jump_columns": ex.jumps.columns,
        "ground_contact_rows": ex.contact_rows,
        "velocity_from_positions": ex.velocity_from_positions,
        "noise_floor": CHANNELS.iter().zip(ex.noise_floor).map(|(c, v)| (c.to_string(), json!(v))).collect::<serde_json::Map<String, serde_json::Value>>(),
        "mismatch_found": ex.mismatch_found,
        "verdict": ex.verdict,
        "located": ex.located,
        "located_channels": ex.located_channels,
        "effects": effects,
        "indistinguishable": ex.indistinguishable,
        "selection_steps": ex.selection_steps,
        "heldout_rms_before": rms(&ex.heldout_rms_before),
        "heldout_rms_after": rms(&ex.heldout_rms_after),
        "multistep_before": ex.multistep_before,
        "multistep_after": ex.multistep_after,
        "ground_effect_gain_grid": ex.ground_effect_gain_grid,
        "motor_lag_profile": ex.motor_lag_profile.iter().map(|(t, c)| json!({"time_constant_s": t, "heldout_error": c})).collect::<Vec<_>>(),
        "timings_s": ex.timings_s,
        "wind_speed": ex.wind_speed,
        "notes": ex.notes,
    })
}

/// The human-readable report.
pub fn report_md(ex: &Explanation) -> String {
    let mut s = String::new();
    report_header(&mut s, ex);
    report_residuals(&mut s, ex);
    report_multistep(&mut s, ex);
    report_where(&mut s, ex);
    report_physics(&mut s, ex);
    report_gain_grid(&mut s, ex);
    let _ = writeln!(s, "\n![effect scores](effects.png)\n");
    let _ = writeln!(
        s,
        "## 4. The model with the fitted effects\n\n[fitted_effects.toml](fitted_effects.toml) (a plant file):\n\n```toml\n{}```",
        ex.fitted_effects_toml
    );
    s
}

/// Title, what was read, the verdict and the notes.
fn report_header(s: &mut String, ex: &Explanation) {
    let _ = writeln!(s, "# Discrepancy report\n");
    let _ = writeln!(
        s,
        "Recording: `{}`, {} rows ({} used) over {:.1} s at {:.0} Hz; Savitzky-Golay window {} samples.\n",
        ex.source, ex.rows, ex.rows_used, ex.duration_s, ex.rate_hz, ex.window_samples
    );
    let vc = &ex.velocity_from_positions;
    let _ = writeln!(
        s,
        "Velocity below {} Hz from the positions: {} (correction RMS x / y / z {:.4} / {:.4} / {:.4} m/s).\n",
        vc.below_hz,
        if vc.applied {
            "applied"
        } else {
            "not applied, see the notes"
        },
        vc.rms[0],
        vc.rms[1],
        vc.rms[2]
    );
    if !ex.ignored_columns.is_empty() {
        let _ = writeln!(s, "Ignored columns: {}.\n", ex.ignored_columns.join(", "));
    }
    if ex.skipped_nonfinite + ex.skipped_time > 0 {
        let _ = writeln!(
            s,
            "Skipped rows: {} non-finite or missing values, {} not advancing in time.\n",
            ex.skipped_nonfinite, ex.skipped_time
        );
    }
    if ex.outliers.rows > 0 {
        let _ = writeln!(
            s,
            "Dropped rows: {} with a cell outside its plausible range (docs/recording_format.md): {}.\n",
            ex.outliers.rows,
            ex.outliers.describe()
        );
    }
    if ex.skipped_rotation > 0 {
        let _ = writeln!(
            s,
            "Skipped rows: {} whose rotation matrix is not a rotation (orthonormal, det +1).\n",
            ex.skipped_rotation
        );
    }
    if ex.jumps.rows > 0 {
        let _ = writeln!(
            s,
            "Dropped rows: {} jumping from their neighbours by more than the robot can accelerate in one sample (docs/input-contract.md): {}.\n",
            ex.jumps.rows,
            ex.jumps.describe()
        );
    }
    if ex.contact_rows > 0 {
        let _ = writeln!(
            s,
            "{} rows with the wheels at the ground were left out (ground contact is not a candidate effect).\n",
            ex.contact_rows
        );
    }
    let _ = writeln!(s, "## Verdict\n\n**{}**\n", ex.verdict);
    for n in &ex.notes {
        let _ = writeln!(s, "Note: {n}.\n");
    }
}

/// Section 1: noise floor and held-out RMS per channel.
fn report_residuals(s: &mut String, ex: &Explanation) {
    let _ = writeln!(
        s,
        "## 1. Residuals\n\nNoise floor per channel (filtered sensor noise and command timing):\n"
    );
    let _ = writeln!(
        s,
        "| channel | floor | held-out RMS before | after | in located region before | after |"
    );
    let _ = writeln!(s, "| --- | --- | --- | --- | --- | --- |");
    for c in 0..6 {
        let _ = writeln!(
            s,
            "| {} ({}) | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} |",
            CHANNELS[c],
            CHANNEL_UNITS[c],
            ex.noise_floor[c],
            ex.heldout_rms_before.per_channel[c],
            ex.heldout_rms_after.per_channel[c],
            ex.heldout_rms_before.located_per_channel[c],
            ex.heldout_rms_after.located_per_channel[c]
        );
    }
    let b = &ex.heldout_rms_before;
    let a = &ex.heldout_rms_after;
    let red = if b.located_normalized > 0.0 {
        100.0 * (1.0 - a.located_normalized / b.located_normalized)
    } else {
        0.0
    };
    let _ = writeln!(
        s,
        "\nIn the located region ({} rows, channels {}): RMS {:.2} -> {:.2} noise floors ({red:.0} % lower, held-out).\n",
        b.located_rows,
        if ex.located_channels.is_empty() {
            "none".into()
        } else {
            ex.located_channels.join(", ")
        },
        b.located_normalized,
        a.located_normalized
    );
}

/// Multi-step prediction errors before and after.
fn report_multistep(s: &mut String, ex: &Explanation) {
    let mb = &ex.multistep_before;
    let ma = &ex.multistep_after;
    if mb.attempted == 0 {
        let _ = writeln!(
            s,
            "Multi-step prediction: no start (no airborne stretch of the horizon in the recording).\n"
        );
        return;
    }
    if mb.starts == 0 {
        let _ = writeln!(
            s,
            "Multi-step prediction: none of the {} starts was replayed by both models (the nominal \
             model failed on {}, the held-out fitted plant files on {}); no error is reported.\n",
            mb.attempted, mb.failed, ma.failed
        );
        return;
    }
    let _ = writeln!(
        s,
        "Multi-step prediction ({:.2} s horizon, {} starts, plant replayed with the recorded commands; after = held-out fitted effects{}):\n",
        mb.horizon_s,
        mb.starts,
        if mb.failed + ma.failed > 0 {
            format!(
                "; of {} starts, {} could not be replayed with the nominal model and {} with the \
                 fitted plant files, and both columns leave them out",
                mb.attempted, mb.failed, ma.failed
            )
        } else {
            String::new()
        }
    );
    let _ = writeln!(
        s,
        "| error at horizon | before | after |\n| --- | --- | --- |"
    );
    let three = |v: [f64; 3]| format!("{:.4}, {:.4}, {:.4}", v[0], v[1], v[2]);
    let rows = [
        ("position (m) x, y, z", mb.position, ma.position),
        ("attitude (rad) yaw, pitch, roll", mb.attitude, ma.attitude),
        ("velocity (m/s) x, y, z", mb.velocity, ma.velocity),
        ("body rates (rad/s) x, y, z", mb.rate, ma.rate),
    ];
    for (name, before, aft) in rows {
        let _ = writeln!(s, "| {name} | {} | {} |", three(before), three(aft));
    }
    s.push('\n');
    let _ = writeln!(s, "![time series](timeseries.png)\n");
}

/// Section 2: the located bins.
fn report_where(s: &mut String, ex: &Explanation) {
    let _ = writeln!(s, "## 2. Where\n");
    if ex.located.is_empty() {
        let _ = writeln!(
            s,
            "No channel and region carries residual beyond the noise floor.\n"
        );
    } else {
        let _ = writeln!(
            s,
            "Bins whose residual is beyond the noise floor (bias or excess variance, family-wise level 0.1 %):\n"
        );
        let _ = writeln!(
            s,
            "| channel | region | rows | mean | RMS | RMS / floor | p |\n| --- | --- | --- | --- | --- | --- | --- |"
        );
        let mut located = ex.located.clone();
        located.sort_by(|a, b| b.rms_ratio.total_cmp(&a.rms_ratio));
        for l in located.iter().take(40) {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.4} | {:.4} | {:.2} | {:.1e} |",
                l.channel, l.region, l.samples, l.mean, l.rms, l.rms_ratio, l.p_value
            );
        }
        if located.len() > 40 {
            let _ = writeln!(s, "\n({} more in explain.json)", located.len() - 40);
        }
    }
    let _ = writeln!(
        s,
        "\n![heat map before](heatmap_before.png) ![heat map after](heatmap_after.png)\n"
    );
}

/// Section 3: every candidate's verdict, confidence and parameters.
fn report_physics(s: &mut String, ex: &Explanation) {
    let _ = writeln!(s, "## 3. Which physics\n");
    let _ = writeln!(
        s,
        "Forward-backward selection on held-out segments; confidence (of found effects only) = inclusion frequency over {} random halves of the segments; high confidence >= {HIGH_CONFIDENCE}.\n",
        crate::selection::STABILITY_RUNS
    );
    let _ = writeln!(
        s,
        "| effect | verdict | confidence | held-out gain | parameters |\n| --- | --- | --- | --- | --- |"
    );
    for e in &ex.effects {
        let params: Vec<String> = e
            .parameters
            .iter()
            .take(if e.name == Effect::GroundEffect { 0 } else { 8 })
            .map(|p| {
                let value = match p.std {
                    Some(sd) => format!("{} = {:.4} +- {:.4} {}", p.name, p.value, sd, p.unit),
                    None => format!("{} = {:.4} {}", p.name, p.value, p.unit),
                };
                if p.identified {
                    value
                } else {
                    format!("{value} (not identified)")
                }
            })
            .collect();
        let mut params = if e.name == Effect::GroundEffect {
            "gain grid below".to_string()
        } else {
            params.join("; ")
        };
        for c in &e.combined {
            let _ = write!(params, "; only in combination: {}", c.describe());
        }
        let verdict = format!(
            "{}{} ({})",
            if e.selected { "found" } else { "rejected" },
            if e.calibration { ", calibration" } else { "" },
            e.decided_by
        );
        let _ = writeln!(
            s,
            "| {} ({}) | {}{} | {} | {:.4} | {} |",
            e.name,
            e.physics,
            verdict,
            if e.indistinguishable_from.is_empty() {
                String::new()
            } else {
                format!(
                    "; cannot be told apart from {}",
                    effects::join(&e.indistinguishable_from, ", ")
                )
            } + &if e.same_finding_as.is_empty() {
                String::new()
            } else {
                format!(
                    "; one finding with {}",
                    effects::join(&e.same_finding_as, ", ")
                )
            },
            e.confidence
                .map_or_else(|| "-".into(), |c| format!("{c:.2}")),
            e.heldout_gain,
            params
        );
    }
}

/// The fitted ground-effect gain grid (when ground effect is selected).
fn report_gain_grid(s: &mut String, ex: &Explanation) {
    if ex
        .effects
        .iter()
        .any(|e| e.name == Effect::GroundEffect && e.selected)
    {
        let _ = writeln!(
            s,
            "\nGround-effect gain T/T_inf - 1 (fitted, +- jackknife sd; * = no data there):\n"
        );
        let _ = writeln!(
            s,
            "| hub height | 0 deg | 40 deg | 50 deg | 60 deg | 70 deg |\n| --- | --- | --- | --- | --- | --- |"
        );
        for h in crate::GRID_HEIGHTS {
            let _ = write!(s, "| {h:.2} m |");
            for v in crate::GRID_TILTS_DEG {
                if let Some(g) = ex
                    .ground_effect_gain_grid
                    .iter()
                    .find(|g| g.height_m == h && g.varphi_deg == v)
                {
                    let _ = write!(
                        s,
                        " {:.3} +- {:.3}{} |",
                        g.gain,
                        g.std,
                        if g.covered { "" } else { " *" }
                    );
                }
            }
            let _ = writeln!(s);
        }
    }
}

fn heat_png(
    path: &Path,
    loc: &Location,
    title: &str,
    floor: &[f64; 6],
) -> Result<(), ExplainError> {
    let root = BitMapBackend::new(path, (760, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(out_err)?;
    let nh = HEIGHT_EDGES.len() - 1;
    let nv = VARPHI_EDGES.len() - 1;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0..nv, 0..nh)
        .map_err(out_err)?;
    let vlabels = ["<15", "15-35", "35-45", "45-55", "55-65", ">65"];
    let hlabels = [
        "<0.25",
        "0.25-0.35",
        "0.35-0.45",
        "0.45-0.6",
        "0.6-0.8",
        "0.8-1.2",
        "1.2-2",
        ">2",
    ];
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("tilt varphi (deg)")
        .y_desc("hub height (m)")
        .x_labels(nv)
        .y_labels(nh)
        .x_label_formatter(&|v| vlabels.get(*v).copied().unwrap_or("").to_string())
        .y_label_formatter(&|h| hlabels.get(*h).copied().unwrap_or("").to_string())
        .draw()
        .map_err(out_err)?;
    for h in 0..nh {
        for v in 0..nv {
            let cell = &loc.heat[h][v];
            if cell[0].samples == 0 {
                continue;
            }
            // RMS over the channels in noise floors.
            let r = ((0..6)
                .map(|c| (cell[c].rms / floor[c]).powi(2))
                .sum::<f64>()
                / 6.0)
                .sqrt();
            // Not finite (a cell of 1e200 in the recording overflows the
            // RMS): the top of the scale. plotters' colormap panics on NaN.
            let x = if r.is_finite() {
                ((r - 1.0) / 4.0).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let color = ViridisRGB::get_color(x);
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(v, h), (v + 1, h + 1)],
                    color.filled(),
                )))
                .map_err(out_err)?;
            let flagged = cell.iter().any(|c| c.flagged);
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{r:.1}{}", if flagged { "*" } else { "" }),
                    (v, h + 1),
                    ("sans-serif", 16)
                        .into_font()
                        .color(&if x > 0.6 { BLACK } else { WHITE }),
                )))
                .map_err(out_err)?;
        }
    }
    root.present().map_err(out_err)?;
    Ok(())
}

fn series_png(path: &Path, ex: &Explanation) -> Result<(), ExplainError> {
    let Some(series) = &ex.series else {
        return Ok(());
    };
    let (ch, t, meas, nom, fit) = (
        &series.channel,
        &series.t,
        &series.recording,
        &series.nominal,
        &series.fitted,
    );
    if t.is_empty() {
        return Ok(());
    }
    let root = BitMapBackend::new(path, (1100, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(out_err)?;
    let Some((lo, hi)) = plotted_range(meas.iter().chain(nom).chain(fit).copied()) else {
        return Ok(()); // no finite value to draw
    };
    let pad = 0.05 * (hi - lo).max(1e-6);
    let (y_lo, y_hi) = (lo - pad, hi + pad);
    let clipped = meas
        .iter()
        .chain(nom)
        .chain(fit)
        .filter(|v| !(y_lo..=y_hi).contains(*v))
        .count();
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{} ({}): recording vs model{}",
                CHANNELS[*ch],
                CHANNEL_UNITS[*ch],
                if clipped > 0 {
                    format!(" ({clipped} values outside the range shown, clipped)")
                } else {
                    String::new()
                }
            ),
            ("sans-serif", 20),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(t[0]..t[t.len() - 1], y_lo..y_hi)
        .map_err(out_err)?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .draw()
        .map_err(out_err)?;
    let pts = |v: &Vec<f64>| {
        t.iter()
            .zip(v)
            .filter(|(_, y)| y.is_finite())
            .map(|(&t, &y)| (t, y.clamp(y_lo, y_hi)))
            .collect::<Vec<_>>()
    };
    chart
        .draw_series(LineSeries::new(pts(meas), BLACK.stroke_width(1)))
        .map_err(out_err)?
        .label("recording")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    chart
        .draw_series(LineSeries::new(pts(nom), RED.stroke_width(1)))
        .map_err(out_err)?
        .label("nominal model (before)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    chart
        .draw_series(LineSeries::new(pts(fit), BLUE.stroke_width(1)))
        .map_err(out_err)?
        .label("with fitted effects (after, held-out)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(out_err)?;
    root.present().map_err(out_err)?;
    Ok(())
}

/// The y range of a time series: its finite values' full range, unless a
/// few absurd cells (`u1 = 1e200`) make that more than 1000 times the range
/// of the 0.5-99.5 % quantiles (or overflow it): then the quantiles, so the
/// axis stays plottable and the rest of the series is not flattened to a
/// line. `None` if no value is finite.
fn plotted_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let mut finite: Vec<f64> = values.filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        return None;
    }
    finite.sort_by(f64::total_cmp);
    let at = |q: f64| finite[((finite.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = (finite[0], finite[finite.len() - 1]);
    let (q_lo, q_hi) = (at(0.005), at(0.995));
    let span = hi - lo;
    if span.is_finite() && span <= 1000.0 * (q_hi - q_lo).max(1e-6) {
        Some((lo, hi))
    } else {
        Some((q_lo, q_hi))
    }
}

fn effects_png(path: &Path, ex: &Explanation) -> Result<(), ExplainError> {
    let root = BitMapBackend::new(path, (800, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(out_err)?;
    let n = ex.effects.len();
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "confidence of the found effects (inclusion frequency)",
            ("sans-serif", 20),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(110)
        .build_cartesian_2d(0.0..1.0, 0..n)
        .map_err(out_err)?;
    let names: Vec<String> = ex.effects.iter().map(|e| e.name.to_string()).collect();
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(n)
        .y_label_formatter(&|i| {
            names
                .get(n.saturating_sub(1 + *i))
                .cloned()
                .unwrap_or_default()
        })
        .draw()
        .map_err(out_err)?;
    // Only a found effect has a confidence; the others get no bar.
    for (i, e) in ex.effects.iter().enumerate() {
        let y = n - 1 - i;
        let Some(confidence) = e.confidence else {
            continue;
        };
        let color = GREEN;
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(0.0, y), (confidence.max(0.005), y + 1)],
                color.filled(),
            )))
            .map_err(out_err)?;
    }
    root.present().map_err(out_err)?;
    Ok(())
}

/// Writes every output into `dir` (created if needed).
pub fn write_all(ex: &Explanation, dir: &Path) -> Result<(), ExplainError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| ExplainError::Output(format!("creating {}: {e}", dir.display())))?;
    let write = |name: &str, text: &str| {
        std::fs::write(dir.join(name), text)
            .map_err(|e| ExplainError::Output(format!("writing {}: {e}", dir.join(name).display())))
    };
    write("fitted_effects.toml", &ex.fitted_effects_toml)?;
    write(
        "explain.json",
        &(serde_json::to_string_pretty(&json(ex)).map_err(out_err)? + "\n"),
    )?;
    write("report.md", &report_md(ex))?;
    if let Some(loc) = &ex.location_before {
        heat_png(
            &dir.join("heatmap_before.png"),
            loc,
            "residual RMS / noise floor, nominal model (* = located)",
            &ex.noise_floor,
        )?;
    }
    if let Some(loc) = &ex.location_after {
        heat_png(
            &dir.join("heatmap_after.png"),
            loc,
            "residual RMS / noise floor, with fitted effects (held-out)",
            &ex.noise_floor,
        )?;
    }
    series_png(&dir.join("timeseries.png"), ex)?;
    effects_png(&dir.join("effects.png"), ex)?;
    Ok(())
}
