//! Recordings: the rows the discrepancy finder reads, and the CSV reader.
//!
//! CSV format (docs/recording_format.md): a header row, then one row per
//! sample, comma-separated, SI units, NED world / FRD body / Euler ZYX.
//! Required columns: `t, x, y, z, yaw, pitch, roll, vx, vy, vz, wx, wy, wz,
//! u1, u2, u3, u4, varphi`. Optional: `ground_z` (NED z of the ground plane
//! under the robot, 0 when absent) and `battery_v`. Unknown columns are
//! ignored and listed; rows with a non-finite value are skipped and counted.
//! Every reader then applies the reader contract ([`contract`]): time base,
//! plausible ranges, and (in the analysis) the neighbour check.

pub mod contract;
pub mod neural_fly;
pub mod plausible;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use atmo_core::model::{Input, State};

use crate::ExplainError;

/// Required columns, in state order then inputs then tilt.
pub const REQUIRED_COLUMNS: [&str; 18] = [
    "t", "x", "y", "z", "yaw", "pitch", "roll", "vx", "vy", "vz", "wx", "wy", "wz", "u1", "u2",
    "u3", "u4", "varphi",
];
/// Topic of the flight stack's tick status in its MCAP logs.
pub const STATUS_TOPIC: &str = "/atmo/status";
/// Optional columns the tool uses.
pub const OPTIONAL_COLUMNS: [&str; 6] = [
    "ground_z",
    "battery_v",
    "u1_mean",
    "u2_mean",
    "u3_mean",
    "u4_mean",
];
/// Optional columns of the mean commands applied until the next row.
pub const MEAN_COMMAND_COLUMNS: [&str; 4] = ["u1_mean", "u2_mean", "u3_mean", "u4_mean"];

/// Most rows of one recording: the memory of the analysis grows with the
/// rows (bytes per row measured in BENCHMARKS.md), so a longer recording is
/// refused with this limit named rather than left to the kernel's OOM
/// killer. 10^6 rows: 1.85 h at 150 Hz.
pub const MAX_ROWS: usize = 1_000_000;
/// Largest recording file read, bytes (1 KiB per row at [`MAX_ROWS`]);
/// checked before the file is read.
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// The error of a recording with more than [`MAX_ROWS`] rows, `at` the
/// place the limit was passed.
pub fn row_limit_error(at: &str) -> String {
    format!(
        "{at}: more than {MAX_ROWS} rows, the analysis's row limit (its memory grows \
         with the rows; see BENCHMARKS.md): split the recording, or decimate it"
    )
}

/// Most columns of a CSV header (a wider header is refused before its names
/// are compared).
pub const MAX_COLUMNS: usize = 4096;

/// Largest time between two consecutive rows of a recording, s.
pub const MAX_ROW_GAP_S: f64 = 10.0;
/// Largest median row spacing of a recording, s (a sample rate of 1 Hz).
pub const MAX_MEDIAN_DT_S: f64 = 1.0;

/// One sample of a recording.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// s.
    pub t: f64,
    /// Rigid-body state (atmo-core order).
    pub x: State,
    /// Normalized rotor commands in effect at `t`.
    pub u: Input,
    /// Mean rotor commands applied over `[t, next row's t)`. Under the
    /// recording format's input timing (commands held from their row's `t`
    /// until the next row) this is `u`; a recording that knows the command
    /// stream between rows (a simulator, the flight stack's ticks, the CSV
    /// columns `u1_mean..u4_mean`) gives the mean of what was applied.
    pub applied: Input,
    /// rad.
    pub varphi: f64,
    /// NED z of the ground plane under the robot (m).
    pub ground_z: f64,
    /// V, if recorded.
    pub battery_v: Option<f64>,
}

/// A recording and what reading it found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    pub source: PathBuf,
    pub samples: Vec<Sample>,
    /// Columns present but not used.
    pub ignored_columns: Vec<String>,
    /// Rows skipped because a value was missing, unparsable or not finite.
    pub skipped_nonfinite: usize,
    /// Rows skipped because their time did not increase.
    pub skipped_time: usize,
    /// Rows dropped because a cell was outside its column's plausible
    /// range ([`plausible`]).
    pub outliers: plausible::Outliers,
    /// Rows skipped because their rotation matrix was not a rotation
    /// (Neural-Fly `R`: [`neural_fly::ROTATION_TOLERANCE`]).
    pub skipped_rotation: usize,
    /// Rows dropped by the neighbour check ([`contract::drop_jumps`]).
    pub jumps: plausible::Outliers,
    /// Where each sample came from (a line number, a message index), for
    /// messages; empty in memory.
    pub at: Vec<usize>,
    /// What [`Recording::at`] counts (`line`, `/atmo/status message`).
    pub at_unit: &'static str,
}

impl Recording {
    /// What the readers dropped, for messages (`dropped 1200 not advancing
    /// in time, 2 with a non-finite or missing value`); `None` if nothing.
    pub fn dropped_rows(&self) -> Option<String> {
        let counts = [
            (self.skipped_nonfinite, "with a non-finite or missing value"),
            (self.skipped_time, "not advancing in time"),
            (
                self.skipped_rotation,
                "whose rotation matrix is not a rotation",
            ),
            (
                self.outliers.rows,
                "with a cell outside its plausible range",
            ),
            (self.jumps.rows, "jumping from their neighbours"),
        ];
        let dropped: Vec<String> = counts
            .iter()
            .filter(|(n, _)| *n > 0)
            .map(|(n, what)| format!("{n} {what}"))
            .collect();
        (!dropped.is_empty()).then(|| format!("dropped {}", dropped.join(", ")))
    }

    /// From samples in memory (tests, generators).
    pub fn from_samples(source: impl Into<PathBuf>, samples: Vec<Sample>) -> Self {
        Self {
            source: source.into(),
            samples,
            ..Self::default()
        }
    }

    /// Reads a recording; the format is chosen by the extension (`.mcap`:
    /// the flight stack's log, anything else: CSV) and, for CSV, by the
    /// header (a Neural-Fly log's header: [`crate::recording::neural_fly`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ExplainError> {
        let path = path.as_ref();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let fail = |message: String| ExplainError::Input {
            file: path.to_path_buf(),
            message,
        };
        if ext == "mcap" {
            contract::check_input(path).map_err(&fail)?;
            return Self::from_mcap(path);
        }
        let bytes = contract::read_input(path).map_err(&fail)?;
        contract::check_text(&bytes).map_err(&fail)?;
        let text = String::from_utf8(bytes).map_err(|e| ExplainError::Input {
            file: path.to_path_buf(),
            message: format!(
                "not a text (UTF-8) CSV file: invalid byte at offset {}",
                e.utf8_error().valid_up_to()
            ),
        })?;
        let header = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
        if neural_fly::is_neural_fly_header(header) {
            return neural_fly::from_neural_fly_str(&text, path);
        }
        Self::from_csv_str(&text, path)
    }

    /// Reads the flight stack's MCAP log: topic [`STATUS_TOPIC`]
    /// (`atmo_msgs/MpcStatus`, one per tick). A row per distinct estimate:
    /// `t` = tick stamp - estimate age (the instant the estimate describes),
    /// the estimated state, the rotor commands of the last tick at or before
    /// that instant, the tilt interpolated between ticks, and the ground
    /// from the logged height (`ground_z = z + height`).
    pub fn from_mcap(path: &Path) -> Result<Self, ExplainError> {
        let fail = |message: String| ExplainError::Input {
            file: path.to_path_buf(),
            message,
        };
        let msgs = atmo_io::mcap_log::read_topic::<atmo_io::msg::MpcStatus>(path, STATUS_TOPIC)
            .map_err(|e| {
                fail(format!(
                    "cannot read the MCAP log ({e}); a log cut short by a killed writer can be \
                     repaired with atmo_io::mcap_log::recover"
                ))
            })?;
        if msgs.is_empty() {
            return Err(fail(format!(
                "the MCAP log has no messages on {STATUS_TOPIC} (atmo_msgs/MpcStatus)"
            )));
        }
        // The ticks' clock goes through the time rule first: one tick with a
        // wild clock would otherwise order every other tick after it.
        let (keep, skipped_ticks) =
            contract::time_order(msgs.len(), |k| msgs[k].1.stamp_ns as f64 * 1e-9);
        let ticks: Vec<(usize, f64, &atmo_io::msg::MpcStatus)> = msgs
            .iter()
            .enumerate()
            .filter(|(k, _)| keep[*k])
            .map(|(k, (_, m))| (k + 1, m.stamp_ns as f64 * 1e-9, m))
            .collect();
        let mut rec = Recording {
            source: path.to_path_buf(),
            skipped_time: skipped_ticks,
            at_unit: "/atmo/status message",
            ..Recording::default()
        };
        let mut last_t = f64::NEG_INFINITY;
        let mut j = 0;
        for &(index, stamp, m) in &ticks {
            if m.estimate_age < 0.0 {
                continue; // no estimate yet
            }
            let t = stamp - m.estimate_age;
            if (t - last_t).abs() < 1e-9 {
                continue; // the same estimate, seen by another tick
            }
            let finite = m.state.iter().all(|v| v.is_finite())
                && m.height.is_finite()
                && m.varphi.is_finite()
                && t.is_finite();
            if !finite {
                rec.skipped_nonfinite += 1;
                continue;
            }
            if t < last_t {
                rec.skipped_time += 1;
                continue;
            }
            // Last tick at or before t: its commands were in effect.
            while j + 1 < ticks.len() && ticks[j + 1].1 <= t + 1e-9 {
                j += 1;
            }
            let (_, t0, m0) = ticks[j];
            if t0 > t + 1e-9 {
                continue; // before the first tick's commands
            }
            let u = m0.thrust;
            if !u.iter().all(|v| v.is_finite()) {
                rec.skipped_nonfinite += 1;
                continue;
            }
            let varphi = match ticks.get(j + 1) {
                Some((_, t1, m1)) if *t1 > t0 => {
                    m0.varphi + (m1.varphi - m0.varphi) * (t - t0) / (t1 - t0)
                }
                _ => m0.varphi,
            };
            if rec.samples.len() == MAX_ROWS {
                return Err(fail(row_limit_error(STATUS_TOPIC)));
            }
            last_t = t;
            rec.at.push(index);
            let x = State::from_column_slice(&m.state);
            let u = Input::from_column_slice(&u);
            rec.samples.push(Sample {
                t,
                x,
                u,
                applied: u,
                varphi,
                ground_z: x[2] + m.height,
                battery_v: None,
            });
        }
        let stream: Vec<(f64, &atmo_io::msg::MpcStatus)> =
            ticks.iter().map(|&(_, t, m)| (t, m)).collect();
        mean_tick_commands(&mut rec.samples, &stream);
        contract::finish(&mut rec).map_err(&fail)?;
        Ok(rec)
    }

    /// Parses CSV text; `file` names the origin in errors. Time rule: `t` in seconds, increasing (rows
    /// that do not advance are skipped and counted), consecutive rows at
    /// most [`MAX_ROW_GAP_S`] apart and the median spacing at most
    /// [`MAX_MEDIAN_DT_S`]; otherwise an error naming the line and values
    /// (timestamps in ms, us or ns, a stray 1e20).
    pub fn from_csv_str(text: &str, file: impl Into<PathBuf>) -> Result<Self, ExplainError> {
        let file = file.into();
        let fail = |message: String| ExplainError::Input {
            file: file.clone(),
            message,
        };
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
        let Some((_, header)) = lines.next() else {
            return Err(fail(
                "the file is empty: expected a header row naming the columns \
                 (t, x, y, z, yaw, pitch, roll, vx, vy, vz, wx, wy, wz, u1..u4, varphi)"
                    .into(),
            ));
        };
        let CsvColumns {
            count,
            required,
            ground,
            battery,
            means,
            ignored: ignored_columns,
        } = csv_columns(header).map_err(&fail)?;
        let mut rec = Recording {
            source: file.clone(),
            ignored_columns,
            at_unit: "line",
            ..Recording::default()
        };
        let mut fields: Vec<&str> = Vec::with_capacity(count);
        let mut values = [0.0; 18];
        for (index, line) in lines {
            fields.clear();
            fields.extend(line.split(','));
            let parse = |i: usize| -> Option<f64> {
                fields
                    .get(i)
                    .and_then(|s| s.trim().parse::<f64>().ok())
                    .filter(|v| v.is_finite())
            };
            let mut ok = true;
            for (k, &col) in required.iter().enumerate() {
                if let Some(v) = parse(col) {
                    values[k] = v;
                } else {
                    ok = false;
                    break;
                }
            }
            let ground_z = match ground {
                Some(g) => parse(g),
                None => Some(0.0),
            };
            let u = Input::from_column_slice(&values[13..17]);
            let applied = if means.is_empty() {
                Some(u)
            } else {
                let m: Vec<f64> = means.iter().filter_map(|&c| parse(c)).collect();
                (m.len() == 4).then(|| Input::from_column_slice(&m))
            };
            let (true, Some(ground_z), Some(applied)) = (ok, ground_z, applied) else {
                rec.skipped_nonfinite += 1;
                continue;
            };
            if rec.samples.len() == MAX_ROWS {
                return Err(fail(row_limit_error(&format!("line {}", index + 1))));
            }
            rec.at.push(index + 1);
            rec.samples.push(Sample {
                t: values[0],
                x: State::from_column_slice(&values[1..13]),
                u,
                applied,
                varphi: values[17],
                ground_z,
                battery_v: battery.and_then(parse),
            });
        }
        contract::finish(&mut rec).map_err(&fail)?;
        Ok(rec)
    }

    /// Writes the recording as CSV (the format [`Recording::from_csv_str`]
    /// reads), with the mean-command columns when any row's applied
    /// commands differ from its `u`.
    pub fn to_csv(&self) -> String {
        let with_means = self.samples.iter().any(|s| s.applied != s.u);
        let mut out = String::with_capacity(self.samples.len() * 260);
        out.push_str(&REQUIRED_COLUMNS.join(","));
        out.push_str(",ground_z");
        if with_means {
            out.push(',');
            out.push_str(&MEAN_COMMAND_COLUMNS.join(","));
        }
        out.push('\n');
        for s in &self.samples {
            let _ = write!(out, "{:.6}", s.t);
            for v in s.x.iter() {
                let _ = write!(out, ",{v:.9}");
            }
            for v in s.u.iter() {
                let _ = write!(out, ",{v:.9}");
            }
            let _ = write!(out, ",{:.9},{:.6}", s.varphi, s.ground_z);
            if with_means {
                for v in s.applied.iter() {
                    let _ = write!(out, ",{v:.9}");
                }
            }
            out.push('\n');
        }
        out
    }

    /// Median time step (s).
    pub fn median_dt(&self) -> f64 {
        let mut d: Vec<f64> = self.samples.windows(2).map(|w| w[1].t - w[0].t).collect();
        if d.is_empty() {
            return 0.0;
        }
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    }
}

/// Where a CSV header puts the columns the reader uses.
struct CsvColumns {
    count: usize,
    /// Of [`REQUIRED_COLUMNS`], in order.
    required: Vec<usize>,
    ground: Option<usize>,
    battery: Option<usize>,
    /// Of [`MEAN_COMMAND_COLUMNS`]: all four or none.
    means: Vec<usize>,
    ignored: Vec<String>,
}

/// Reads the header row: every required column present once, the mean
/// commands all four or none; otherwise the message naming what is wrong.
fn csv_columns(header: &str) -> Result<CsvColumns, String> {
    let count = header.split(',').count();
    if count > MAX_COLUMNS {
        return Err(format!(
            "the header has {count} columns, over the limit of {MAX_COLUMNS} \
             (a recording has 18 to 24; is the first line data?)"
        ));
    }
    let names: Vec<String> = header
        .trim_start_matches('\u{feff}')
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .collect();
    let find = |name: &str| names.iter().position(|n| n == name);
    let missing: Vec<&str> = REQUIRED_COLUMNS
        .iter()
        .copied()
        .filter(|c| find(c).is_none())
        .collect();
    if !missing.is_empty() {
        return Err(format!(
            "missing required column{} {} (header has: {})",
            if missing.len() > 1 { "s" } else { "" },
            missing
                .iter()
                .map(|m| format!("`{m}`"))
                .collect::<Vec<_>>()
                .join(", "),
            names.join(", ")
        ));
    }
    let mut seen = std::collections::HashSet::with_capacity(names.len());
    if let Some(n) = names.iter().find(|n| !seen.insert(n.as_str())) {
        return Err(format!("column `{n}` appears twice in the header"));
    }
    let required: Vec<usize> = REQUIRED_COLUMNS
        .iter()
        .map(|c| find(c).unwrap_or(0))
        .collect();
    let ground = find("ground_z");
    let battery = find("battery_v");
    let means: Vec<usize> = MEAN_COMMAND_COLUMNS
        .iter()
        .filter_map(|c| find(c))
        .collect();
    if !means.is_empty() && means.len() != 4 {
        return Err(format!(
            "columns {}: give all four or none (header has: {})",
            MEAN_COMMAND_COLUMNS.join(", "),
            names.join(", ")
        ));
    }
    let ignored_columns: Vec<String> = names
        .iter()
        .filter(|n| {
            !REQUIRED_COLUMNS.contains(&n.as_str()) && !OPTIONAL_COLUMNS.contains(&n.as_str())
        })
        .cloned()
        .collect();
    Ok(CsvColumns {
        count: names.len(),
        required,
        ground,
        battery,
        means,
        ignored: ignored_columns,
    })
}

/// The mean of the ticks' commands over each row's interval to the next
/// row (the last row keeps its own): the flight stack's logs know when every
/// command was applied. Ticks with non-finite commands are passed over.
fn mean_tick_commands(samples: &mut [Sample], ticks: &[(f64, &atmo_io::msg::MpcStatus)]) {
    let stream: Vec<(f64, Input)> = ticks
        .iter()
        .filter(|(_, m)| m.thrust.iter().all(|v| v.is_finite()))
        .map(|(t, m)| (*t, Input::from_column_slice(&m.thrust)))
        .collect();
    if stream.is_empty() {
        return;
    }
    let mut j = 0;
    for k in 0..samples.len().saturating_sub(1) {
        let (a, b) = (samples[k].t, samples[k + 1].t);
        while j + 1 < stream.len() && stream[j + 1].0 <= a + 1e-9 {
            j += 1;
        }
        let mut sum = Input::zeros();
        let mut at = a;
        let mut i = j;
        loop {
            let until = stream.get(i + 1).map_or(b, |(t, _)| t.min(b));
            sum += stream[i].1 * (until - at).max(0.0);
            at = until;
            if at >= b || i + 1 >= stream.len() {
                break;
            }
            i += 1;
        }
        samples[k].applied = sum / (b - a);
    }
}

#[cfg(test)]
mod time_axis_tests {
    use super::Recording;

    fn csv(times: &[&str]) -> String {
        let mut text =
            String::from("t,x,y,z,yaw,pitch,roll,vx,vy,vz,wx,wy,wz,u1,u2,u3,u4,varphi\n");
        for t in times {
            text.push_str(t);
            text.push_str(",0,0,1,0,0,0,0,0,0,0,0,0,0.5,0.5,0.5,0.5,0\n");
        }
        text
    }

    /// 1e20, 1.7e12, a gap of 1e19 s and us timestamps panicked,
    /// aborted or hung; now an error naming the line and the value.
    #[test]
    fn implausible_time_axes_are_refused_with_line_and_value() {
        let cases: [(&[&str], &str); 4] = [
            (&["0", "0.01", "1e20", "1e20"], "line 4: t = 1e20"),
            (&["0", "0.01", "1700000000000"], "line 4: t = 1.7e12"),
            (&["0", "1e19"], "line 3: t = 1e19"),
            (&["0", "8333", "16666", "25000"], "line 3: t = 8333"),
        ];
        for (times, expected) in cases {
            let err = Recording::from_csv_str(&csv(times), "r.csv")
                .unwrap_err()
                .to_string();
            assert!(err.contains(expected) && err.contains("r.csv"), "{err}");
        }
        let slow = ["0", "2", "4", "6"];
        let err = Recording::from_csv_str(&csv(&slow), "r.csv")
            .unwrap_err()
            .to_string();
        assert!(err.contains("median spacing of the rows is 2 s"), "{err}");
        let fine = ["0", "0.01", "0.02", "0.03"];
        assert_eq!(
            Recording::from_csv_str(&csv(&fine), "r.csv")
                .unwrap()
                .samples
                .len(),
            4
        );
    }
}
