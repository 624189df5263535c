//! The `atmo-sim explain` command: read (or, with `--demo`, generate) a
//! recording, analyse it, write the outputs, print the verdict. [`Args`]
//! is flattened into the binary's subcommand; the binary draws the
//! progress bar from the [`Progress`] reports.

use std::path::{Path, PathBuf};

use atmo_core::{ConfigFile, RobotConfig};

use crate::effects::Effect;
use crate::output::write_all;
use crate::recording::Recording;
use crate::synth::{Flight, Profile, record};
use crate::{ExplainError, Options, Progress, explain_with_progress};
use atmo_core::ground_effect::table::GroundEffectConfig;
use atmo_plant::config::{
    BatterySagConfig, ComOffsetConfig, DragConfig, EffectsConfig, MassErrorConfig, MotorLagConfig,
    PlantConfig, SensorsConfig, WindConfig,
};

/// Discrepancy finder: where a recording and the model disagree, which
/// missing physics explains it, and the fit with it.
///
/// INPUT: a CSV recording with a header row and the columns t, x, y, z,
/// yaw, pitch, roll, vx, vy, vz, wx, wy, wz, u1, u2, u3, u4, varphi (SI
/// units, rad; NED world, FRD body, Euler ZYX, world velocity, body
/// rates, normalized rotor commands); optional ground_z (NED z of the
/// ground, 0 if absent) and battery_v. Unknown columns are ignored and
/// listed; non-finite or time-reversing rows are skipped and counted.
/// See docs/recording_format.md. A file ending in .mcap is read as the
/// flight stack's log (topic /atmo/status, atmo_msgs/MpcStatus).
/// Or --demo EFFECTS: generate a recording of the built-in plant with
/// those effects concealed (e.g. --demo ground_effect,motor_lag).
///
/// WHAT IT DOES: acceleration residuals of the nominal model (the robot
/// file only; Savitzky-Golay differentiation, window from the data
/// rate), multi-step (0.5 s) prediction error, located by channel and
/// by height, tilt, speed, thrust, time and command rate against the
/// noise floor; candidate effects (ground_effect, motor_lag, drag, wind,
/// thrust_scale, battery_sag, com_offset, inertia_error, mass_error)
/// selected on held-out segments, with parameters, uncertainty and
/// confidence.
///
/// OUTPUTS in --out: report.md, explain.json (mismatch_found, located,
/// effects, heldout_rms_before/after, ground_effect_gain_grid, ...),
/// fitted_effects.toml (a plant file: PlantConfig::load reads it),
/// heatmap_before.png, heatmap_after.png, timeseries.png, effects.png;
/// recording.csv with --demo. Exit status 0 also when a mismatch is
/// found; errors (bad input) exit non-zero with a message naming the
/// file and the problem.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Recording: CSV, or the flight stack's MCAP log (*.mcap); see
    /// docs/recording_format.md.
    pub recording: Option<PathBuf>,
    /// Robot parameter file: the nominal model.
    #[arg(long, default_value = "config/atmo.toml")]
    pub robot: PathBuf,
    /// Output folder.
    #[arg(long, default_value = "out/explain")]
    pub out: PathBuf,
    /// Generate the recording instead: comma-separated effects to
    /// conceal (ground_effect, motor_lag, drag, wind, battery_sag,
    /// com_offset, mass_error, none).
    #[arg(long)]
    pub demo: Option<String>,
    /// Length of a --demo recording, s (at most 3600).
    #[arg(long, default_value_t = 48.0, value_parser = atmo_core::cli_numbers::demo_duration_s)]
    pub duration: f64,
    /// Sample rate of a --demo recording, Hz (at most 1000).
    #[arg(long, default_value_t = 120.0, value_parser = atmo_core::cli_numbers::sample_rate_hz)]
    pub rate: f64,
    /// Seed (demo flight and stability subsampling).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Wall-clock budget of the analysis, s: a run that takes longer still
    /// finishes, and says so (a note in the verdict, report.md and
    /// explain.json, with its slowest stage).
    #[arg(long, default_value_t = crate::DEFAULT_BUDGET_S,
          value_parser = atmo_core::cli_numbers::analysis_budget_s)]
    pub budget: f64,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
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

/// Runs the command, telling `progress` where the analysis is; returns
/// what to print.
///
/// Refused before anything is read, generated or written: an `--out` that
/// is not a folder this tool wrote (`atmo_io::output_dir`), a `--demo` whose
/// `--duration` x `--rate` passes the row limit.
pub fn run(args: &Args, progress: &mut dyn FnMut(Progress)) -> Result<String, ExplainError> {
    let robot = RobotConfig::load(&args.robot)?;
    // Staged: a run that fails leaves an earlier run's folder as it was.
    let out = atmo_io::output_dir::StagedDir::new(&args.out)
        .map_err(|e| ExplainError::Output(e.to_string()))?;
    let rec = match (&args.recording, &args.demo) {
        (Some(path), None) => Recording::load(path)?,
        (None, Some(list)) => {
            demo_within_row_limit(args.duration, args.rate)?;
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
            let path = out.path().join("recording.csv");
            std::fs::write(&path, rec.to_csv())
                .map_err(|e| ExplainError::Output(format!("writing {}: {e}", path.display())))?;
            Recording {
                source: args.out.join("recording.csv"),
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
        budget_s: args.budget,
        ..Options::default()
    };
    let start = std::time::Instant::now();
    let ex = explain_with_progress(&rec, &robot, &opts, progress)?;
    let elapsed = start.elapsed().as_secs_f64();
    write_all(&ex, out.path())?;
    out.commit()
        .map_err(|e| ExplainError::Output(e.to_string()))?;
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
            .filter(|_| e.name != Effect::GroundEffect)
            .map(|p| {
                if p.identified {
                    match p.std {
                        Some(sd) => format!("{} = {:.4} +- {:.4}", p.name, p.value, sd),
                        None => format!("{} = {:.4}", p.name, p.value),
                    }
                } else {
                    format!("{} not identified", p.name)
                }
            })
            .collect();
        let _ = writeln!(
            s,
            "  {:<14} confidence {}  {}",
            e.name,
            e.confidence
                .map_or_else(|| "-".into(), |c| format!("{c:.2}")),
            params.join(", ")
        );
        for c in &e.combined {
            let _ = writeln!(s, "  {:<14} only in combination: {}", "", c.describe());
        }
    }
    let b = &ex.heldout_rms_before;
    let a = &ex.heldout_rms_after;
    let _ = writeln!(
        s,
        "located region {} rows; held-out RMS {:.2} -> {:.2} noise floors",
        b.located_rows, b.located_normalized, a.located_normalized
    );
    let (mb, ma) = (&ex.multistep_before, &ex.multistep_after);
    let _ = if mb.attempted == 0 {
        writeln!(
            s,
            "multi-step     none: no airborne stretch of {:.2} s to start from",
            crate::HORIZON
        )
    } else if mb.starts == 0 {
        writeln!(
            s,
            "multi-step     none: no start of {} replayed by both models (nominal failed on {}, \
             fitted on {})",
            mb.attempted, mb.failed, ma.failed
        )
    } else {
        writeln!(
            s,
            "multi-step     {:.2} s: position {:.4} -> {:.4} m, velocity {:.4} -> {:.4} m/s{}",
            mb.horizon_s,
            mb.position_norm(),
            ma.position_norm(),
            mb.velocity_norm(),
            ma.velocity_norm(),
            if mb.failed + ma.failed > 0 {
                format!(
                    " ({} of {} starts: nominal failed on {}, fitted on {})",
                    mb.starts, mb.attempted, mb.failed, ma.failed
                )
            } else {
                String::new()
            }
        )
    };
    let _ = writeln!(s, "analysed in    {elapsed:.2} s");
    let _ = writeln!(
        s,
        "outputs        {}/{{report.md, explain.json, fitted_effects.toml, *.png}}",
        out.display()
    );
    s
}

/// A `--demo` of `duration` s at `rate` Hz must fit the row limit
/// ([`crate::recording::MAX_ROWS`]); checked before generating it (3600 s at
/// 1000 Hz generated for minutes what the limit then refused).
pub fn demo_within_row_limit(duration: f64, rate: f64) -> Result<(), ExplainError> {
    let rows = (duration * rate).ceil();
    let max = crate::recording::MAX_ROWS as f64;
    if rows.is_finite() && rows <= max {
        return Ok(());
    }
    Err(ExplainError::Input {
        file: PathBuf::from("--demo"),
        message: format!(
            "--duration {duration} s at --rate {rate} Hz is {rows} rows, over the row limit of \
             {max} (lower --duration or --rate)"
        ),
    })
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    #[derive(Parser)]
    struct Explain {
        #[command(flatten)]
        args: super::Args,
    }

    /// `--demo --duration inf` panicked, `1e9` aborted allocating.
    #[test]
    fn demo_duration_and_rate_are_finite_and_bounded() {
        for (flag, value) in [
            ("--duration", "inf"),
            ("--duration", "1e9"),
            ("--duration", "nan"),
            ("--rate", "inf"),
            ("--rate", "0"),
            ("--rate", "1e7"),
        ] {
            let err = Explain::try_parse_from(["explain", "--demo", "none", flag, value])
                .err()
                .unwrap_or_else(|| panic!("{flag} {value} accepted"));
            let text = err.to_string();
            assert!(text.contains(flag) && text.contains(value), "{text}");
        }
        let ok = Explain::try_parse_from(["explain", "--demo", "none", "--duration", "12"]);
        assert_eq!(ok.map(|e| e.args.duration).ok(), Some(12.0));
    }

    /// `--demo --duration 3600 --rate 1000` generated for minutes what the
    /// row limit then refused; refused before generating, and `--out` at a
    /// file is refused before anything moves.
    #[test]
    fn a_demo_over_the_row_limit_and_an_out_at_a_file_are_refused_up_front() {
        let dir = std::env::temp_dir().join(format!("atmo-cli-upfront-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_default();
        let out = dir.join("out");
        let e = Explain::try_parse_from([
            "explain",
            "--robot",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/atmo.toml"),
            "--demo",
            "none",
            "--duration",
            "3600",
            "--rate",
            "1000",
            "--out",
            &out.display().to_string(),
        ]);
        let Ok(e) = e else { panic!("parse") };
        let start = std::time::Instant::now();
        let err = super::run(&e.args, &mut |_| {})
            .map(|_| ())
            .map_err(|e| e.to_string());
        let Err(err) = err else { panic!("accepted") };
        assert!(start.elapsed().as_secs_f64() < 5.0);
        assert!(err.contains("3600000 rows, over the row limit"), "{err}");
        assert!(!out.exists());

        let file = dir.join("notes.txt");
        std::fs::write(&file, b"keep me").unwrap_or_default();
        let e = Explain::try_parse_from([
            "explain",
            "--robot",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/atmo.toml"),
            "--demo",
            "none",
            "--duration",
            "12",
            "--out",
            &file.display().to_string(),
        ]);
        let Ok(e) = e else { panic!("parse") };
        let err = super::run(&e.args, &mut |_| {})
            .map(|_| ())
            .map_err(|e| e.to_string());
        let Err(err) = err else { panic!("accepted") };
        assert!(err.contains("exists and is a file"), "{err}");
        assert_eq!(std::fs::read(&file).ok().as_deref(), Some(&b"keep me"[..]));
        let left: Vec<_> = std::fs::read_dir(&dir)
            .map(|d| d.filter_map(Result::ok).map(|e| e.file_name()).collect())
            .unwrap_or_default();
        assert_eq!(left, [std::ffi::OsString::from("notes.txt")]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A robot file that cannot be read is named once (it was named twice:
    /// "/dev/zero: /dev/zero: cannot read ..."), and a `--rate` the plant's
    /// sensors refuse is refused on the command line with the same range.
    #[test]
    fn a_bad_robot_file_is_named_once_and_the_rate_takes_the_sensors_range() {
        let e = Explain::try_parse_from(["explain", "--robot", "/nonexistent/robot.toml"]);
        let Ok(e) = e else { panic!("parse") };
        let err = super::run(&e.args, &mut |_| {})
            .map(|_| ())
            .map_err(|e| e.to_string());
        let Err(err) = err else { panic!("accepted") };
        assert_eq!(err.matches("/nonexistent/robot.toml").count(), 1, "{err}");
        let rate = Explain::try_parse_from(["explain", "--demo", "none", "--rate", "0.5"]);
        let Err(rate) = rate else {
            panic!("0.5 Hz accepted")
        };
        assert!(rate.to_string().contains("in [1, 1000]"), "{rate}");
    }
}
