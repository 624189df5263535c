//! The `atmo-sim explain` command: read (or, with `--demo`, generate) a
//! recording, analyse it, write the outputs, print the verdict.

use std::path::{Path, PathBuf};

use atmo_core::{ConfigFile, RobotConfig};

use crate::output::write_all;
use crate::recording::Recording;
use crate::synth::{Flight, Profile, record};
use crate::{ExplainError, Options, explain};
use atmo_plant::config::{
    BatterySagConfig, ComOffsetConfig, DragConfig, EffectsConfig, MassErrorConfig, MotorLagConfig,
    PlantConfig, SensorsConfig, WindConfig,
};
use atmo_plant::ground_effect::GroundEffectConfig;

/// Arguments of the command.
#[derive(Debug, Clone)]
pub struct Args {
    pub recording: Option<PathBuf>,
    pub robot: PathBuf,
    pub out: PathBuf,
    /// Comma-separated effects to conceal in a generated recording.
    pub demo: Option<String>,
    /// Length of a generated recording (s).
    pub duration: f64,
    /// Sample rate of a generated recording (Hz).
    pub rate: f64,
    pub seed: u64,
    pub progress: bool,
}

/// Plant effects for `--demo` (plant defaults, steady wind 2 m/s north).
pub fn demo_effects(list: &str) -> Result<EffectsConfig, ExplainError> {
    let mut fx = EffectsConfig::none();
    for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        match name {
            "none" => {}
            "ground_effect" => fx.ground_effect = Some(GroundEffectConfig::default()),
            "motor_lag" => fx.motor_lag = Some(MotorLagConfig::default()),
            "drag" => fx.drag = Some(DragConfig::default()),
            "wind" => {
                fx.wind = Some(WindConfig {
                    steady: [2.0, 0.0, 0.0],
                    turbulence_std: [0.0; 3],
                    ..WindConfig::default()
                });
            }
            "battery_sag" => fx.battery_sag = Some(BatterySagConfig::default()),
            "com_offset" => {
                fx.com_offset = Some(ComOffsetConfig {
                    enabled: true,
                    offset: [0.005, -0.003, 0.0],
                });
            }
            "mass_error" => fx.mass_error = Some(MassErrorConfig::default()),
            other => {
                return Err(ExplainError::Input {
                    file: PathBuf::from("--demo"),
                    message: format!(
                        "unknown effect `{other}` (ground_effect, motor_lag, drag, wind, \
                         battery_sag, com_offset, mass_error, none)"
                    ),
                });
            }
        }
    }
    Ok(fx)
}

/// Runs the command; returns what to print.
pub fn run(args: &Args) -> Result<String, ExplainError> {
    let robot = RobotConfig::load(&args.robot).map_err(|e| ExplainError::Input {
        file: args.robot.clone(),
        message: e.to_string(),
    })?;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| ExplainError::Output(format!("creating {}: {e}", args.out.display())))?;
    let rec = match (&args.recording, &args.demo) {
        (Some(path), None) => Recording::load(path)?,
        (None, Some(list)) => {
            let mut plant = PlantConfig::ideal();
            plant.arm_inertia_convention = robot.arm.inertia_convention;
            plant.effects = demo_effects(list)?;
            plant.effects.sensors = Some(SensorsConfig {
                rate_hz: args.rate,
                ..SensorsConfig::default()
            });
            let flight = Flight::new(Profile::Mixed, args.duration, args.seed);
            let rec = record(&robot, &plant, &flight)
                .map_err(|e| ExplainError::Output(format!("generating the demo: {e}")))?;
            let path = args.out.join("recording.csv");
            std::fs::write(&path, rec.to_csv())
                .map_err(|e| ExplainError::Output(format!("writing {}: {e}", path.display())))?;
            Recording {
                source: path,
                ..rec
            }
        }
        (Some(_), Some(_)) => {
            return Err(ExplainError::Input {
                file: PathBuf::from("--demo"),
                message: "give either a recording or --demo, not both".into(),
            });
        }
        (None, None) => {
            return Err(ExplainError::Input {
                file: PathBuf::from("(none)"),
                message: "no recording given (a CSV file, or --demo EFFECTS to generate one)"
                    .into(),
            });
        }
    };
    let opts = Options {
        seed: args.seed,
        progress: args.progress,
        ..Options::default()
    };
    let start = std::time::Instant::now();
    let ex = explain(&rec, &robot, &opts)?;
    let elapsed = start.elapsed().as_secs_f64();
    write_all(&ex, &args.out)?;
    Ok(summary(&ex, &args.out, elapsed))
}

fn summary(ex: &crate::Explanation, out: &Path, elapsed: f64) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "recording      {} ({} rows, {:.1} s at {:.0} Hz)",
        ex.source, ex.rows, ex.duration_s, ex.rate_hz
    );
    let _ = writeln!(s, "verdict        {}", ex.verdict);
    for n in &ex.notes {
        let _ = writeln!(s, "note           {n}");
    }
    for e in ex.effects.iter().filter(|e| e.selected) {
        let params: Vec<String> = e
            .parameters
            .iter()
            .take(if e.name == "ground_effect" { 0 } else { 4 })
            .map(|p| format!("{} = {:.4}", p.name, p.value))
            .collect();
        let _ = writeln!(
            s,
            "  {:<14} confidence {:.2}  {}",
            e.name,
            e.confidence,
            params.join(", ")
        );
    }
    let b = &ex.heldout_rms_before;
    let a = &ex.heldout_rms_after;
    let _ = writeln!(
        s,
        "located region {} rows; held-out RMS {:.2} -> {:.2} noise floors",
        b.located_rows, b.located_normalized, a.located_normalized
    );
    let _ = writeln!(
        s,
        "multi-step     {:.2} s: position {:.4} -> {:.4} m, velocity {:.4} -> {:.4} m/s",
        ex.multistep_before.horizon_s,
        ex.multistep_before.position_norm(),
        ex.multistep_after.position_norm(),
        ex.multistep_before.velocity_norm(),
        ex.multistep_after.velocity_norm()
    );
    let _ = writeln!(s, "analysed in    {elapsed:.2} s");
    let _ = writeln!(
        s,
        "outputs        {}/{{report.md, explain.json, fitted_effects.toml, *.png}}",
        out.display()
    );
    s
}
