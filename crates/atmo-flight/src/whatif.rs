//! What-if replay output: the logged and the changed flight stack's
//! outputs tick by tick (`whatif.csv`, and the series `atmo-daemon replay`
//! plots as `whatif.png`), and the largest difference of every compared
//! field.

use std::fmt::Write as _;
use std::path::Path;

use atmo_io::msg::MpcStatus;

use crate::error::{FlightError, Result};
use crate::replay::{TickPair, compared_fields};

/// Printed with every what-if result.
pub const OPEN_LOOP_NOTE: &str = "open loop w.r.t. the plant: the changed flight stack sees the inputs as recorded (estimate, encoder, contact), not as its own commands would have made them";

/// The largest difference of one field over the flight.
#[derive(Debug, Clone, PartialEq)]
pub struct LargestDifference {
    pub field: String,
    /// |logged - what-if| (modes and solver states by code).
    pub size: f64,
    pub tick: u64,
    pub time_s: f64,
    pub logged: String,
    pub replayed: String,
    /// Ticks on which the field differs.
    pub ticks: usize,
}

/// The per-tick comparison of a what-if replay.
#[derive(Debug, Clone, Default)]
pub struct WhatIfTable {
    time: Vec<f64>,
    logged: Vec<MpcStatus>,
    replayed: Vec<MpcStatus>,
    largest: Vec<LargestDifference>,
}

fn mean(thrust: &[f64; 4]) -> f64 {
    thrust.iter().sum::<f64>() / 4.0
}

impl WhatIfTable {
    /// Adds one replayed tick.
    pub fn push(&mut self, pair: &TickPair<'_>) {
        self.time.push(pair.time_s);
        self.logged.push(*pair.logged);
        self.replayed.push(*pair.replayed);
        let fields = compared_fields(pair.logged)
            .into_iter()
            .zip(compared_fields(pair.replayed));
        for (i, ((field, a), (_, b))) in fields.enumerate() {
            if self.largest.len() <= i {
                self.largest.push(LargestDifference {
                    field,
                    size: 0.0,
                    tick: 0,
                    time_s: 0.0,
                    logged: String::new(),
                    replayed: String::new(),
                    ticks: 0,
                });
            }
            if a.identical(&b) {
                continue;
            }
            let entry = &mut self.largest[i];
            entry.ticks += 1;
            let size = (a.number() - b.number()).abs();
            // A NaN against a number counts as the largest difference.
            let size = if size.is_nan() { f64::INFINITY } else { size };
            if entry.ticks == 1 || size > entry.size {
                entry.size = size;
                entry.tick = pair.tick;
                entry.time_s = pair.time_s;
                entry.logged = a.to_string();
                entry.replayed = b.to_string();
            }
        }
    }

    /// The fields that differ, largest first by the number of ticks they
    /// differ on, one line each.
    pub fn largest_differences(&self) -> Vec<String> {
        let mut differing: Vec<&LargestDifference> =
            self.largest.iter().filter(|d| d.ticks > 0).collect();
        differing.sort_by(|a, b| b.ticks.cmp(&a.ticks).then(a.field.cmp(&b.field)));
        if differing.is_empty() {
            return vec!["no field differs".into()];
        }
        differing
            .iter()
            .map(|d| {
                format!(
                    "{:<26} differs on {:>5} ticks; largest {:.6} at tick {} (t = {:.3} s): logged {}, what-if {}",
                    d.field, d.ticks, d.size, d.tick, d.time_s, d.logged, d.replayed
                )
            })
            .collect()
    }

    /// The per-field largest differences.
    pub fn differences(&self) -> &[LargestDifference] {
        &self.largest
    }

    /// The table as CSV (one row per tick, logged and what-if side by side).
    pub fn csv(&self) -> String {
        let mut out = String::from(
            "tick,time_s,mode_logged,mode_whatif,height_logged_m,height_whatif_m,tilt_logged_deg,tilt_whatif_deg,tilt_velocity_logged,tilt_velocity_whatif,mean_thrust_logged,mean_thrust_whatif,thrust0_logged,thrust0_whatif,thrust1_logged,thrust1_whatif,thrust2_logged,thrust2_whatif,thrust3_logged,thrust3_whatif,solver_logged,solver_whatif\n",
        );
        for ((t, a), b) in self.time.iter().zip(&self.logged).zip(&self.replayed) {
            let _ = write!(
                out,
                "{},{t:?},{},{},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?}",
                a.tick,
                a.mode.name(),
                b.mode.name(),
                a.height,
                b.height,
                a.varphi.to_degrees(),
                b.varphi.to_degrees(),
                a.tilt_velocity,
                b.tilt_velocity,
                mean(&a.thrust),
                mean(&b.thrust),
            );
            for i in 0..4 {
                let _ = write!(out, ",{:?},{:?}", a.thrust[i], b.thrust[i]);
            }
            let _ = writeln!(
                out,
                ",{},{}",
                a.solver_status.name(),
                b.solver_status.name()
            );
        }
        out
    }

    /// Writes `whatif.csv` and `whatif.txt` (the largest differences and
    /// the open-loop note) into `dir`; the overlay figure is the binary's
    /// (`atmo-daemon replay`), which links the plotting.
    ///
    /// # Errors
    /// A file that cannot be written.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let write_err =
            |file: &Path, e: std::io::Error| FlightError::Setup(format!("{}: {e}", file.display()));
        std::fs::create_dir_all(dir).map_err(|e| write_err(dir, e))?;
        let csv = dir.join("whatif.csv");
        std::fs::write(&csv, self.csv()).map_err(|e| write_err(&csv, e))?;
        let txt = dir.join("whatif.txt");
        let mut text = format!("{OPEN_LOOP_NOTE}\n\nlargest differences:\n");
        for line in self.largest_differences() {
            text.push_str(&line);
            text.push('\n');
        }
        std::fs::write(&txt, text).map_err(|e| write_err(&txt, e))?;
        Ok(())
    }

    /// The replayed ticks' times, s.
    pub fn time(&self) -> &[f64] {
        &self.time
    }

    /// One quantity of every tick, logged and what-if.
    pub fn series(&self, f: fn(&MpcStatus) -> f64) -> (Vec<f64>, Vec<f64>) {
        (
            self.logged.iter().map(f).collect(),
            self.replayed.iter().map(f).collect(),
        )
    }
}

/// The mean of a tick's four thruster commands.
pub fn mean_thrust(status: &MpcStatus) -> f64 {
    mean(&status.thrust)
}
