//! How much of the Neural-Fly authors' residual force `fa` the fitted model
//! predicts (the real-flight target: an MSE cut of >= 80 % at 100 %
//! fan on held-out data).
//!
//! `fa = m a - m g - T_auth`, with their thrust `T_auth = m g (T_sp /
//! hover_throttle) R e_z` (docs/neural_fly.md; z-up world). The model's
//! prediction of it: `fa_hat = m a_model - m g - T_auth`, where `a_model` is
//! the measured acceleration minus the analysis's held-out residual (each row
//! predicted by the fit on the other folds of whole segments, 5-fold
//! cross-validation; the nominal model alone for the baseline). Then
//! `cut = 1 - mean |fa - fa_hat|^2 / mean |fa|^2` over the rows the analysis
//! used. `fa` comes from the authors' raw differentiation, `a` from
//! explain's Savitzky-Golay filter: their difference is in `fa - fa_hat` too,
//! so the cut is bounded below 100 % by that noise.
//!
//! `cargo run --release -p atmo-explain --example neural_fly_fa -- [FLIGHT.csv]
//! [--robot config/neural_fly_quadrotor.toml] [--second-half | --fit-first-half]`
//! (FLIGHT defaults to the committed 12 s of L1 at 100 % fan; the whole
//! flights are the Neural-Fly data set's, aerorobotics/neural-fly,
//! `data/experiment`).
//!
//! `--second-half`: only the rows of the second half of the flight count
//! (the fit still uses all folds but a row's own).
//!
//! `--fit-first-half`: the whole analysis ([`atmo_explain::analyse`], the
//! stages `explain` runs: screening, the velocity's slow band from the
//! positions, motor-lag and wind profiles, selection, fit, acceptance)
//! runs on the first half of the flight alone, as on a file of it; its
//! model (effects, knobs, coefficients) then predicts the second half,
//! which it never saw (its velocity taken from its positions the same
//! way), and only the second half's rows are scored. The
//! regressors of the second half are built as the selection builds them:
//! once on the nominal accelerations, then again on the fitted model's
//! (the mass-property columns need the model's acceleration).
#![allow(clippy::unwrap_used)] // reason: a measurement script, errors abort it

use std::collections::HashMap;

use atmo_core::ConfigFile as _;
use atmo_core::RobotConfig;
use atmo_explain::recording::Recording;
use atmo_explain::recording::neural_fly::split_row;
use atmo_explain::stages::Residuals;
use nalgebra::{Matrix3, Vector3};

const G: f64 = 9.81;

/// Per row time: (fa, T_sp / hover_throttle, R) from the CSV.
fn authors_columns(text: &str) -> HashMap<u64, ([f64; 3], f64, Matrix3<f64>)> {
    let mut lines = text.lines();
    let header = split_row(lines.next().unwrap());
    let col = |name: &str| header.iter().position(|h| h.trim() == name).unwrap();
    let (ct, cfa, ctsp, chov, cr) = (
        col("t"),
        col("fa"),
        col("T_sp"),
        col("hover_throttle"),
        col("R"),
    );
    let mut out = HashMap::new();
    for line in lines {
        let cells = split_row(line);
        let num = |c: usize| -> Vec<f64> {
            let s = cells[c];
            if s.starts_with('[') {
                let v: serde_json::Value = serde_json::from_str(s).unwrap();
                let mut flat = Vec::new();
                flatten(&v, &mut flat);
                flat
            } else {
                vec![s.parse().unwrap()]
            }
        };
        let t = num(ct)[0];
        let fa = num(cfa);
        let r = Matrix3::from_row_slice(&num(cr));
        out.insert(
            t.to_bits(),
            ([fa[0], fa[1], fa[2]], num(ctsp)[0] / num(chov)[0], r),
        );
    }
    out
}

fn flatten(v: &serde_json::Value, out: &mut Vec<f64>) {
    match v {
        serde_json::Value::Array(items) => items.iter().for_each(|i| flatten(i, out)),
        serde_json::Value::Number(n) => out.push(n.as_f64().unwrap()),
        _ => {}
    }
}

/// How much of the Neural-Fly authors' residual force `fa` the finder's
/// fitted model predicts (see the example's documentation).
#[derive(clap::Parser)]
struct Args {
    /// A Neural-Fly flight in the authors' CSV format (the repository
    /// carries 12 s pieces of two of them: crates/atmo-explain/tests/data,
    /// sources in its README).
    #[arg(default_value = "crates/atmo-explain/tests/data/neural_fly_L1_100wind_12s.csv")]
    flight: String,
    /// Robot file: the nominal model.
    #[arg(long, default_value = "config/neural_fly_quadrotor.toml")]
    robot: String,
    /// Score only the second half's rows (the fit still uses every fold
    /// but a row's own).
    #[arg(long)]
    second_half: bool,
    /// Run the whole analysis on the first half alone; its model predicts
    /// the second half, which alone is scored.
    #[arg(long)]
    fit_first_half: bool,
}

fn main() {
    let args = <Args as clap::Parser>::parse();
    let path = &args.flight;
    let fit_first_half = args.fit_first_half;
    let second_half = fit_first_half || args.second_half;
    let robot = RobotConfig::load(&args.robot).unwrap();
    let recorded = Recording::load(path).unwrap();
    let t_split = 0.5 * (recorded.samples[0].t + recorded.samples[recorded.samples.len() - 1].t);
    let half = |first: bool| {
        Recording::from_samples(
            path.as_str(),
            recorded
                .samples
                .iter()
                .filter(|s| (s.t < t_split) == first)
                .copied()
                .collect(),
        )
    };
    let (analysed, unseen) = if fit_first_half {
        (half(true), Some(half(false)))
    } else {
        (recorded.clone(), None)
    };
    let text = std::fs::read_to_string(path).unwrap();
    let authors = authors_columns(&text);

    // The analysis `explain` runs, stage for stage.
    let analysis =
        atmo_explain::analyse(&analysed, &robot, &atmo_explain::Options::default()).unwrap();
    if let Some(w) = &analysis.fit.wind {
        println!(
            "  wind profile: ({:.2}, {:.2}) +- ({:.2}, {:.2}) m/s, weighted RSS {:.4e} against {:.4e} without wind, {} trials",
            w.wind[0], w.wind[1], w.sd[0], w.sd[1], w.rss, w.rss_no_wind, w.evaluations
        );
    }
    for (e, d) in &analysis.decisions {
        println!("  {}: {}", e.name(), d.describe());
    }
    let fit = &analysis.fit;
    // Scored on the unseen half with the first half's model (its velocity
    // taken from the positions as the analysis takes it), or on this
    // recording's held-out folds.
    let scored = if let Some(rec2) = unseen {
        let rec2 = atmo_explain::velocity::from_positions(&rec2).0.into_owned();
        let res2 = Residuals::new(&rec2, &robot).unwrap();
        let after = fit.residual_on_unseen(&res2, &rec2);
        (rec2, res2, after)
    } else {
        let atmo_explain::Analysis {
            rec,
            res,
            validation,
            ..
        } = analysis;
        (rec, res, validation.after)
    };
    let (rec, res, after) = (&scored.0, &scored.1, &scored.2);
    let prep = &res.prep;
    let mass = prep.table.at(0.0).mass;
    let flip = Vector3::new(1.0, -1.0, -1.0);
    let t_mid = 0.5 * (prep.t[0] + prep.t[prep.n - 1]);

    let mut sum_fa = 0.0;
    let mut sum_nominal = 0.0;
    let mut sum_fitted = 0.0;
    let mut sum_identity = 0.0;
    let mut rows = 0usize;
    for &k in &res.fit_rows {
        if second_half && !fit_first_half && prep.t[k] < t_mid {
            continue;
        }
        let Some((fa, thrust_ratio, r)) = authors.get(&rec.samples[k].t.to_bits()) else {
            continue;
        };
        let fa = Vector3::from(*fa);
        let lin =
            |v: &[f64]| Vector3::new(v[6 * k], v[6 * k + 1], v[6 * k + 2]).component_mul(&flip);
        // Everything in their z-up world frame.
        let a_meas = lin(&prep.meas);
        let thrust = mass * G * thrust_ratio * r.column(2);
        let gravity = Vector3::new(0.0, 0.0, -G * mass);
        let predict = |a_model: Vector3<f64>| mass * a_model - gravity - thrust;
        sum_fa += fa.norm_squared();
        sum_identity += (fa - predict(a_meas)).norm_squared();
        sum_nominal += (fa - predict(a_meas - lin(&prep.resid))).norm_squared();
        sum_fitted += (fa - predict(a_meas - lin(after))).norm_squared();
        rows += 1;
    }
    let n = rows.max(1) as f64;
    let cut = |s: f64| 100.0 * (1.0 - s / sum_fa);
    println!(
        "{path}: {rows} rows{}, mass {mass:.3} kg",
        if fit_first_half {
            " (second half, model fitted on the first half)"
        } else if second_half {
            " (second half)"
        } else {
            ""
        }
    );
    println!(
        "  effects: {:?}",
        fit.chosen.iter().map(|e| e.name()).collect::<Vec<_>>()
    );
    println!("  mean |fa|^2 {:.3} N^2", sum_fa / n);
    println!(
        "  fa against m a - m g - T_auth with explain's filtered a (the noise bound): residual {:.3} N^2, cut {:.1} %",
        sum_identity / n,
        cut(sum_identity)
    );
    println!(
        "  nominal model: residual {:.3} N^2, cut {:.1} %",
        sum_nominal / n,
        cut(sum_nominal)
    );
    println!(
        "  fitted model ({}): residual {:.3} N^2, cut {:.1} %",
        if fit_first_half {
            "first half's fit"
        } else {
            "held-out folds"
        },
        sum_fitted / n,
        cut(sum_fitted)
    );
}
