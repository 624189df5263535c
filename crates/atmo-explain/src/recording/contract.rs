//! The reader contract: the checks every recording goes through after
//! parsing, whatever its format (CSV, Neural-Fly, MCAP, in memory).
//!
//! docs/input-contract.md states it for users. In order:
//!
//! 1. **Input file** ([`read_input`], the rule of every input:
//!    [`atmo_core::input_file`]): a regular file (not a device, FIFO or
//!    folder), at most [`super::MAX_FILE_BYTES`], checked before reading and
//!    read through a bounded reader.
//! 2. **Time base** ([`order_rows`], [`check_time_axis`]): rows whose time
//!    does not increase are skipped and counted; a row that jumps forward
//!    more than [`super::MAX_ROW_GAP_S`] and is followed by rows that carry
//!    on from before it is a time glitch, skipped and counted the same way.
//!    Then the median spacing (at most [`super::MAX_MEDIAN_DT_S`]), every gap
//!    (at most [`super::MAX_ROW_GAP_S`]) and the span (at most
//!    [`MAX_DURATION_S`]) are checked; a violation is refused naming the
//!    line (or message) and the unit the times look like (ms, us, ns).
//! 3. **Ranges**: every cell against its column's plausible range
//!    ([`super::plausible`]).
//! 4. **Neighbours** ([`drop_jumps`], during the analysis, which knows the
//!    robot): a sample whose velocity or body rate jumps away from the
//!    previous one by more than the robot can accelerate in that time, and
//!    whose successors return to the previous level within
//!    [`MAX_GLITCH_ROWS`] rows, is a glitch: dropped and counted per column
//!    with its line.
//!
//! Nothing downstream (the figures, the replay) sizes anything from the
//! time axis before these checks pass.

use std::path::Path;

use atmo_core::RobotConfig;
use atmo_core::input_file::{self, InputKind};
use atmo_core::model::Model;

use super::plausible::{ColumnOutliers, Outliers};
use super::{MAX_FILE_BYTES, MAX_MEDIAN_DT_S, MAX_ROW_GAP_S, Recording, Sample};

/// Longest span of a recording, s (11.6 days; a recording at the slowest
/// accepted median rate of 1 Hz and [`super::MAX_ROWS`] rows).
pub const MAX_DURATION_S: f64 = 1e6;
/// Most consecutive rows a glitch may span and still be recognized as one
/// (a longer excursion is taken as motion).
pub const MAX_GLITCH_ROWS: usize = 3;
/// The margin on the robot's largest acceleration in the neighbour check.
pub const JUMP_MARGIN: f64 = 3.0;
/// Allowance for measurement noise between two samples: velocity, m/s.
pub const VELOCITY_NOISE: f64 = 1.0;
/// Allowance for measurement noise between two samples: body rate, rad/s.
pub const RATE_NOISE: f64 = 3.0;

/// A recording as an input file ([`atmo_core::input_file`]).
pub const RECORDING: InputKind = InputKind {
    name: "a recording",
    max_bytes: MAX_FILE_BYTES,
    advice: "split the recording, or decimate it",
};

/// Reads an input file whole: a regular file of at most
/// [`MAX_FILE_BYTES`], the read itself bounded too (a file that grows while
/// read). Errors are messages for the caller to put the path on.
pub fn read_input(path: &Path) -> Result<Vec<u8>, String> {
    input_file::read(path, RECORDING).map_err(|e| input_error(&e))
}

/// Checks that `path` is a regular file of at most [`MAX_FILE_BYTES`]
/// without reading it (a reader of its own reads it next).
pub fn check_input(path: &Path) -> Result<(), String> {
    input_file::check(path, RECORDING)
        .map(|_| ())
        .map_err(|e| input_error(&e))
}

/// A refusal is its own message; the operating system's errors say they
/// are a failed read.
fn input_error(e: &std::io::Error) -> String {
    if e.kind() == std::io::ErrorKind::InvalidInput {
        e.to_string()
    } else {
        format!("cannot read the file: {e}")
    }
}

/// Refuses a CSV file holding a NUL byte (binary data, not text).
pub fn check_text(bytes: &[u8]) -> Result<(), String> {
    if let Some(at) = bytes.iter().position(|&b| b == 0) {
        return Err(format!(
            "not a text (UTF-8) CSV file: NUL byte at offset {at}"
        ));
    }
    Ok(())
}

/// Where sample `i` came from: `line N` of a CSV file, `message N of TOPIC`
/// of a log, `row N` in memory.
pub fn label(rec: &Recording, i: usize) -> String {
    match (rec.at.get(i), rec.at_unit.is_empty()) {
        (Some(n), false) => format!("{} {n}", rec.at_unit),
        _ => format!("row {}", i + 1),
    }
}

/// Keeps the samples (and their origins) whose `keep` is true.
pub fn retain(rec: &mut Recording, keep: &[bool]) {
    let mut i = 0;
    rec.samples.retain(|_| {
        i += 1;
        keep[i - 1]
    });
    if rec.at.len() == keep.len() {
        let mut i = 0;
        rec.at.retain(|_| {
            i += 1;
            keep[i - 1]
        });
    }
}

/// Skips (and counts in `skipped_time`) the rows whose time does not
/// increase, and forward time glitches: a row more than [`MAX_ROW_GAP_S`]
/// after the previous kept one whose successor goes back to between the two
/// (a clock read wrongly once: `clock_ns = 9e18` in one tick, `t = 1e300`
/// in one row). Keeping the glitch instead would skip every row after it.
pub fn order_rows(rec: &mut Recording) {
    let (keep, skipped) = time_order(rec.samples.len(), |k| rec.samples[k].t);
    rec.skipped_time += skipped;
    if skipped > 0 {
        retain(rec, &keep);
    }
}

/// The rule of [`order_rows`] on `n` times `t(k)`: which to keep, and how
/// many were not.
pub fn time_order(n: usize, t: impl Fn(usize) -> f64) -> (Vec<bool>, usize) {
    let mut keep = vec![true; n];
    let mut skipped = 0;
    let mut kept: Vec<usize> = Vec::with_capacity(n.min(1 << 20));
    for k in 0..n {
        let tk = t(k);
        if let Some(&a) = kept.last() {
            let ta = t(a);
            if tk.partial_cmp(&ta) != Some(std::cmp::Ordering::Greater) {
                skipped += 1;
                let before = kept.len().checked_sub(2).map(|p| t(kept[p]));
                match before {
                    Some(tp) if tk > tp && tk < ta && ta - tp > MAX_ROW_GAP_S => {
                        keep[a] = false;
                        kept.pop();
                    }
                    _ => {
                        keep[k] = false;
                        continue;
                    }
                }
            }
        }
        kept.push(k);
    }
    (keep, skipped)
}

/// A time for a message: plainly up to 1e7, in exponent form beyond (a
/// `t = 1e300` is not printed as 301 digits).
fn t_text(t: f64) -> String {
    if t.abs() < 1e7 {
        format!("{t}")
    } else {
        format!("{t:e}")
    }
}

/// The unit the times look like when read as seconds gives a median spacing
/// of `dt`: an advice for the error message.
fn unit_hint(dt: f64) -> &'static str {
    let plausible = |d: f64| (1e-4..=MAX_MEDIAN_DT_S).contains(&d);
    if plausible(dt / 1e3) {
        "t looks like milliseconds (divide by 1000)"
    } else if plausible(dt / 1e6) {
        "t looks like microseconds (divide by 1e6)"
    } else if plausible(dt / 1e9) {
        "t looks like nanoseconds (divide by 1e9)"
    } else {
        "t must be seconds, not ms, us or ns"
    }
}

/// Checks the time axis of samples in increasing time (see the module
/// docs): median spacing, gaps, span. The error names the row and the unit
/// the times look like.
pub fn check_time_axis(rec: &Recording) -> Result<(), String> {
    let s = &rec.samples;
    if let Some(k) = (1..s.len()).find(|&k| {
        s[k].t
            .partial_cmp(&s[k - 1].t)
            .is_none_or(std::cmp::Ordering::is_le)
    }) {
        return Err(format!(
            "{}: t = {} does not advance past {} ({}): the samples must be in increasing time",
            label(rec, k),
            t_text(s[k].t),
            label(rec, k - 1),
            t_text(s[k - 1].t)
        ));
    }
    if s.len() < 2 {
        return Ok(());
    }
    let dt = rec.median_dt();
    if let Some(k) = (1..s.len()).find(|&k| s[k].t - s[k - 1].t > MAX_ROW_GAP_S) {
        return Err(format!(
            "{}: t = {} is {} s after {} (t = {}): gaps over {MAX_ROW_GAP_S} s are refused \
             (median spacing {} s; {})",
            label(rec, k),
            t_text(s[k].t),
            t_text(s[k].t - s[k - 1].t),
            label(rec, k - 1),
            t_text(s[k - 1].t),
            t_text(dt),
            if dt > MAX_MEDIAN_DT_S || dt.is_nan() {
                unit_hint(dt)
            } else {
                "split the recording at the gap (t must be seconds)"
            }
        ));
    }
    if dt.is_nan() || dt > MAX_MEDIAN_DT_S {
        return Err(format!(
            "column t: the median spacing of the rows is {} s, over {MAX_MEDIAN_DT_S} s \
             (a rate under 1 Hz): {}",
            t_text(dt),
            unit_hint(dt)
        ));
    }
    let span = s[s.len() - 1].t - s[0].t;
    if span > MAX_DURATION_S {
        return Err(format!(
            "column t: the recording spans {} s, over the {MAX_DURATION_S} s limit",
            t_text(span)
        ));
    }
    Ok(())
}

/// The bounds of the neighbour check, from a robot file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JumpBounds {
    /// m/s^2: full thrust over the mass plus gravity, times [`JUMP_MARGIN`].
    pub acceleration: f64,
    /// rad/s^2: the rotors' largest torque over the smallest principal
    /// moment of inertia (tilt 0 and the flight limit), times [`JUMP_MARGIN`].
    pub angular_acceleration: f64,
}

impl JumpBounds {
    pub fn of(robot: &RobotConfig) -> Self {
        let model = Model::new(robot);
        let acceleration = JUMP_MARGIN * (model.max_total_thrust() / model.mass() + model.gravity);
        let mut angular: f64 = 0.0;
        for varphi in [0.0, robot.limits.tilt_flight_max()] {
            let body = model.at_tilt(varphi);
            let torque: f64 = (0..4)
                .map(|i| body.thrust_torque.column(i).norm())
                .sum::<f64>();
            let min_inertia = body.inertia.symmetric_eigenvalues().min();
            if min_inertia > 0.0 && torque.is_finite() {
                angular = angular.max(torque / min_inertia);
            }
        }
        Self {
            acceleration,
            angular_acceleration: JUMP_MARGIN * angular.max(1.0),
        }
    }

    /// The largest change of channel `c` (0..6: vx, vy, vz, wx, wy, wz)
    /// between two samples `dt` apart.
    fn allowed(&self, c: usize, dt: f64) -> f64 {
        if c < 3 {
            VELOCITY_NOISE + self.acceleration * dt
        } else {
            RATE_NOISE + self.angular_acceleration * dt
        }
    }

    /// The channels of `b` that moved from `a` by more than allowed.
    fn jumps(&self, a: &Sample, b: &Sample) -> [bool; 6] {
        let dt = (b.t - a.t).abs();
        let mut out = [false; 6];
        for (c, o) in out.iter_mut().enumerate() {
            let d = (b.x[6 + c] - a.x[6 + c]).abs();
            // Beyond the bound, or not comparable (NaN): a jump.
            *o = d
                .partial_cmp(&self.allowed(c, dt))
                .is_none_or(std::cmp::Ordering::is_gt);
        }
        out
    }
}

/// Column names of the neighbour check's channels.
const JUMP_COLUMNS: [&str; 6] = ["vx", "vy", "vz", "wx", "wy", "wz"];

/// Which samples the neighbour check drops (see the module docs), with the
/// counts per column; `None` when every sample stays.
pub fn find_jumps(rec: &Recording, bounds: &JumpBounds) -> Option<(Vec<bool>, Outliers)> {
    let s = &rec.samples;
    let n = s.len();
    let mut keep = vec![true; n];
    let mut counts = [0usize; 6];
    let mut first: [Option<(usize, f64)>; 6] = [None; 6];
    let any = |j: [bool; 6]| j.iter().any(|b| *b);
    let mut a = 0;
    // A glitch in the first row: it disagrees with the next two, which agree.
    if n > 2
        && any(bounds.jumps(&s[0], &s[1]))
        && any(bounds.jumps(&s[0], &s[2]))
        && !any(bounds.jumps(&s[1], &s[2]))
    {
        keep[0] = false;
        for (c, j) in bounds.jumps(&s[1], &s[0]).iter().enumerate() {
            if *j {
                counts[c] += 1;
                first[c].get_or_insert((0, s[0].x[6 + c]));
            }
        }
        a = 1;
    }
    let mut k = a + 1;
    while k < n {
        if any(bounds.jumps(&s[a], &s[k])) {
            let back = (k + 1..(k + 1 + MAX_GLITCH_ROWS).min(n))
                .find(|&j| !any(bounds.jumps(&s[a], &s[j])));
            if let Some(j) = back {
                for i in k..j {
                    keep[i] = false;
                    for (c, jumped) in bounds.jumps(&s[a], &s[i]).iter().enumerate() {
                        if *jumped {
                            counts[c] += 1;
                            first[c].get_or_insert((i, s[i].x[6 + c]));
                        }
                    }
                }
                a = j;
                k = j + 1;
                continue;
            }
        }
        a = k;
        k += 1;
    }
    let rows = keep.iter().filter(|k| !**k).count();
    if rows == 0 {
        return None;
    }
    let columns = (0..6)
        .filter_map(|c| {
            first[c].map(|(i, v)| ColumnOutliers {
                column: JUMP_COLUMNS[c],
                rows: counts[c],
                first_at: label(rec, i),
                first_value: v,
            })
        })
        .collect();
    Some((keep, Outliers { rows, columns }))
}

/// Applies the neighbour check to `rec`: drops the glitches and counts them
/// in `rec.jumps`.
pub fn drop_jumps(rec: &mut Recording, bounds: &JumpBounds) {
    if let Some((keep, found)) = find_jumps(rec, bounds) {
        retain(rec, &keep);
        rec.jumps.rows += found.rows;
        rec.jumps.columns.extend(found.columns);
    }
}

/// The checks every reader runs after parsing (time base, then ranges);
/// the error is the message for the caller to put the file on.
/// A recording left without a row is refused with what was dropped.
pub fn finish(rec: &mut Recording) -> Result<(), String> {
    order_rows(rec);
    check_time_axis(rec)?;
    let (keep, outliers) = super::plausible::screen(&rec.samples, |i| label(rec, i))?;
    if outliers.rows > 0 {
        retain(rec, &keep);
    }
    rec.outliers.rows += outliers.rows;
    rec.outliers.columns.extend(outliers.columns);
    if rec.samples.is_empty() {
        return Err(rec.dropped_rows().map_or_else(
            || "no usable rows: the file holds no data rows".into(),
            |dropped| format!("no usable rows ({dropped})"),
        ));
    }
    Ok(())
}
