//! `atmo-testgen`: writes a recording (docs/recording_format.md) of a
//! flight simulated without the flight stack.

use std::path::PathBuf;

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
    /// Fixed tilt of the flight (deg).
    #[arg(long, default_value_t = 0.0)]
    tilt_deg: f64,
    /// Length (s).
    #[arg(long, default_value_t = 48.0)]
    duration: f64,
    /// Recording and control rate (Hz).
    #[arg(long, default_value_t = 150.0)]
    rate: f64,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output CSV.
    #[arg(long)]
    out: PathBuf,
}

fn main() -> Result<(), GenError> {
    let args = Args::parse();
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
