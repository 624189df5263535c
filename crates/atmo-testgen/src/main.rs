//! `atmo-testgen`: writes a recording (docs/recording_format.md) of a
//! flight simulated without the flight stack.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

use atmo_testgen::control::ControllerKind;
use atmo_testgen::flight::{FlightPlan, fly, to_csv};
use atmo_testgen::robot::{RigidBody, RobotFile};
use atmo_testgen::{Form, GenError, concealed};

/// An independent recording generator for `atmo-sim explain`.
#[derive(Debug, Parser)]
struct Args {
    /// Robot file (ATMO's format).
    #[arg(long, default_value = "config/atmo.toml")]
    robot: PathBuf,
    /// Concealed effects, comma-separated (ground_effect, motor_lag, drag,
    /// wind, com_offset, thrust_scale, thrust_curve, none).
    #[arg(long, default_value = "none")]
    effects: String,
    /// Which implementation and values of the effects (see the crate's
    /// `Form`: `first` as the finder's tests began with, `second` another
    /// law for each).
    #[arg(long, value_enum, default_value_t = Form::First)]
    form: Form,
    /// The control law flying the flight.
    #[arg(long, value_enum, default_value_t = ControllerKind::Pid)]
    controller: ControllerKind,
    /// Fixed tilt of the flight, deg in [0, 90].
    #[arg(long, default_value_t = 0.0, value_parser = |t: &str| within(t, "deg", 0.0, 90.0))]
    tilt_deg: f64,
    /// Length, s in [0.01, 3600].
    #[arg(long, default_value_t = 48.0, value_parser = |t: &str| within(t, "s", 0.01, 3600.0))]
    duration: f64,
    /// Recording and control rate, Hz in [1, 1000].
    #[arg(long, default_value_t = 150.0, value_parser = |t: &str| within(t, "Hz", 1.0, 1000.0))]
    rate: f64,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output CSV.
    #[arg(long)]
    out: PathBuf,
}

/// A finite number of `unit` in `[lo, hi]`: `1e300` s of flight sized a
/// buffer past memory (a panic), a rate of 0 wrote an empty file.
fn within(text: &str, unit: &str, lo: f64, hi: f64) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (lo..=hi).contains(&v) => Ok(v),
        _ => Err(format!(
            "{text} is not a finite number of {unit} in [{lo}, {hi}]"
        )),
    }
}

fn main() -> ExitCode {
    match generate(&Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("atmo-testgen: {e}");
            ExitCode::FAILURE
        }
    }
}

fn generate(args: &Args) -> Result<(), GenError> {
    let robot = RobotFile::load(&args.robot)?;
    let body = RigidBody::at_tilt(&robot, args.tilt_deg.to_radians());
    let plan = FlightPlan {
        duration: args.duration,
        rate_hz: args.rate,
        seed: args.seed,
        controller: args.controller,
        ..FlightPlan::default()
    };
    let rows = fly(&body, &concealed(&args.effects, args.form)?, &plan);
    std::fs::write(&args.out, to_csv(&rows)).map_err(|e| GenError::Output {
        file: args.out.display().to_string(),
        message: e.to_string(),
    })?;
    println!("{} rows -> {}", rows.len(), args.out.display());
    Ok(())
}
