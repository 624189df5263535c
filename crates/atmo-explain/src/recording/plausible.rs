//! Plausible ranges of a recording's columns, and the outlier rule.
//!
//! A finite value can still be impossible: `vx = 1e100`, a rotor command of
//! 1500 (PWM microseconds, not the normalized command), a tilt of 65
//! (degrees, not radians). One such cell used to steer the whole analysis
//! (the noise floor of a channel became 4e17 m/s^2 and the verdict flipped
//! to "no mismatch"), and a column in the wrong unit was "explained" as
//! physics (PWM commands fitted as a thrust scale of confidence 1.00).
//!
//! The rule (docs/recording_format.md): every cell is checked against its
//! column's range in [`RANGES`] (a robot of this class, SI units, with a
//! wide margin). A row with a cell outside is dropped and counted per
//! column ([`Outliers`]: in `report.md` and `explain.json`), and the rows
//! around it become separate stretches (the gap rule), so an outlier never
//! enters a residual, a noise floor or a fit. When a column has more than
//! [`MAX_OUTLIER_FRACTION`] of its rows outside (and more than one), the
//! values are not outliers but a unit or a convention: the recording is
//! refused, naming the column, the range, the first offending row and its
//! value.

use serde::Serialize;

use super::Sample;

/// A column's physically plausible range (inclusive) and what a value
/// outside usually means.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColumnRange {
    pub column: &'static str,
    pub min: f64,
    pub max: f64,
    pub hint: &'static str,
}

const fn range(column: &'static str, min: f64, max: f64, hint: &'static str) -> ColumnRange {
    ColumnRange {
        column,
        min,
        max,
        hint,
    }
}

const POSITION: &str = "positions are metres from the origin (10 km at most)";
const ANGLE: &str = "angles are radians (one turn either way at most), not degrees";
const YAW: &str = "yaw is radians (an unwrapped yaw of up to 1000 rad is allowed), not degrees";
const VELOCITY: &str = "velocities are m/s (100 m/s at most), not mm/s or cm/s \
                        (or the flight ran away)";
const RATE: &str = "body rates are rad/s (100 rad/s at most), not deg/s";
const COMMAND: &str = "rotor commands are normalized to [0, 1] (a 10 % margin is allowed), \
                       not PWM microseconds, percent or RPM";
const TILT: &str = "the tilt is radians in [0, pi/2] (0 = quadrotor, pi/2 = drive), not degrees";

/// The range of every column a [`Sample`] holds, in the order of
/// `cells`: state (12), commands u1..u4, mean commands, varphi, ground_z.
pub const RANGES: [ColumnRange; 22] = [
    range("x", -1e4, 1e4, POSITION),
    range("y", -1e4, 1e4, POSITION),
    range("z", -1e4, 1e4, POSITION),
    range("yaw", -1e3, 1e3, YAW),
    range(
        "pitch",
        -std::f64::consts::TAU,
        std::f64::consts::TAU,
        ANGLE,
    ),
    range("roll", -std::f64::consts::TAU, std::f64::consts::TAU, ANGLE),
    range("vx", -100.0, 100.0, VELOCITY),
    range("vy", -100.0, 100.0, VELOCITY),
    range("vz", -100.0, 100.0, VELOCITY),
    range("wx", -100.0, 100.0, RATE),
    range("wy", -100.0, 100.0, RATE),
    range("wz", -100.0, 100.0, RATE),
    range("u1", -0.1, 1.1, COMMAND),
    range("u2", -0.1, 1.1, COMMAND),
    range("u3", -0.1, 1.1, COMMAND),
    range("u4", -0.1, 1.1, COMMAND),
    range("u1_mean", -0.1, 1.1, COMMAND),
    range("u2_mean", -0.1, 1.1, COMMAND),
    range("u3_mean", -0.1, 1.1, COMMAND),
    range("u4_mean", -0.1, 1.1, COMMAND),
    range("varphi", -0.1, std::f64::consts::FRAC_PI_2 + 0.1, TILT),
    range("ground_z", -1e4, 1e4, POSITION),
];

/// Above this fraction of a column's rows outside its range, the column is
/// in a wrong unit and the recording is refused.
pub const MAX_OUTLIER_FRACTION: f64 = 0.01;

/// The values of `s` in the order of [`RANGES`].
fn cells(s: &Sample) -> [f64; 22] {
    let mut v = [0.0; 22];
    v[..12].copy_from_slice(s.x.as_slice());
    v[12..16].copy_from_slice(s.u.as_slice());
    v[16..20].copy_from_slice(s.applied.as_slice());
    v[20] = s.varphi;
    v[21] = s.ground_z;
    v
}

/// Whether every cell of `s` is in its column's range.
pub fn is_plausible(s: &Sample) -> bool {
    cells(s)
        .iter()
        .zip(&RANGES)
        .all(|(v, r)| (r.min..=r.max).contains(v))
}

/// One column's cells outside its range.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ColumnOutliers {
    pub column: &'static str,
    /// Rows with this column outside its range.
    pub rows: usize,
    /// Where the first one was (`line N` of a CSV file, `row N` otherwise).
    pub first_at: String,
    pub first_value: f64,
}

/// What the outlier rule dropped.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Outliers {
    /// Rows dropped (a row with several bad cells counts once).
    pub rows: usize,
    /// Per column, in the order of [`RANGES`].
    pub columns: Vec<ColumnOutliers>,
}

impl Outliers {
    /// `column: rows (first at ...: value)`, for reports.
    pub fn describe(&self) -> String {
        self.columns
            .iter()
            .map(|c| {
                format!(
                    "{} {} (first at {}: {:e})",
                    c.column, c.rows, c.first_at, c.first_value
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Applies the rule to `samples` (see the module docs): drops the rows with
/// a cell outside its range and returns what was dropped, or the refusal
/// naming the column, its range, the first offending row (`label(i)` of
/// sample `i`) and its value.
pub fn drop_implausible(
    samples: &mut Vec<Sample>,
    label: impl Fn(usize) -> String,
) -> Result<Outliers, String> {
    let (keep, out) = screen(samples, label)?;
    if out.rows > 0 {
        let mut i = 0;
        samples.retain(|_| {
            i += 1;
            keep[i - 1]
        });
    }
    Ok(out)
}

/// The rule without changing `samples`: which rows to keep and what the
/// others were, or the refusal (see [`drop_implausible`]).
pub fn screen(
    samples: &[Sample],
    label: impl Fn(usize) -> String,
) -> Result<(Vec<bool>, Outliers), String> {
    let total = samples.len();
    let mut counts = [0usize; 22];
    let mut first: [Option<(usize, f64)>; 22] = [None; 22];
    let mut keep = vec![true; total];
    for (i, s) in samples.iter().enumerate() {
        for (k, (v, r)) in cells(s).iter().zip(&RANGES).enumerate() {
            if !(r.min..=r.max).contains(v) {
                counts[k] += 1;
                first[k].get_or_insert((i, *v));
                keep[i] = false;
            }
        }
    }
    let allowed = ((total as f64 * MAX_OUTLIER_FRACTION) as usize).max(1);
    if let Some(k) = (0..RANGES.len()).find(|&k| counts[k] > allowed) {
        let r = &RANGES[k];
        let (i, v) = first[k].unwrap_or((0, f64::NAN));
        return Err(format!(
            "column {}: {} of {total} rows outside the plausible range [{}, {}] \
             (first at {}: {} = {v}): {}; more than {} % of the rows is a unit or a \
             convention, not an outlier",
            r.column,
            counts[k],
            r.min,
            r.max,
            label(i),
            r.column,
            r.hint,
            MAX_OUTLIER_FRACTION * 100.0
        ));
    }
    let mut out = Outliers {
        rows: keep.iter().filter(|k| !**k).count(),
        columns: Vec::new(),
    };
    for k in 0..RANGES.len() {
        if let Some((i, v)) = first[k] {
            out.columns.push(ColumnOutliers {
                column: RANGES[k].column,
                rows: counts[k],
                first_at: label(i),
                first_value: v,
            });
        }
    }
    Ok((keep, out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use atmo_core::model::{Input, State};

    fn sample(t: f64) -> Sample {
        Sample {
            t,
            x: State::zeros(),
            u: Input::from_element(0.5),
            applied: Input::from_element(0.5),
            varphi: 0.2,
            ground_z: 0.0,
            battery_v: None,
        }
    }

    #[test]
    fn one_outlier_is_dropped_and_counted_a_unit_is_refused() {
        let mut samples: Vec<Sample> = (0..200).map(|i| sample(f64::from(i) * 0.01)).collect();
        samples[17].x[6] = 1e100;
        samples[17].u[0] = 1e20;
        let out = drop_implausible(&mut samples, |i| format!("row {}", i + 1)).unwrap();
        assert_eq!(samples.len(), 199);
        assert_eq!(out.rows, 1);
        assert_eq!(
            out.describe(),
            "vx 1 (first at row 18: 1e100), u1 1 (first at row 18: 1e20)"
        );

        let mut pwm: Vec<Sample> = (0..200).map(|i| sample(f64::from(i) * 0.01)).collect();
        for s in &mut pwm {
            s.u = Input::from_element(1500.0);
            s.applied = s.u;
        }
        let err = drop_implausible(&mut pwm, |i| format!("line {}", i + 2)).unwrap_err();
        assert!(
            err.starts_with("column u1: 200 of 200 rows outside the plausible range [-0.1, 1.1] (first at line 2: u1 = 1500)")
                && err.contains("PWM"),
            "{err}"
        );
        assert_eq!(pwm.len(), 200, "a refused recording is left as it was");

        let mut degrees: Vec<Sample> = (0..200).map(|i| sample(f64::from(i) * 0.01)).collect();
        for s in &mut degrees {
            s.varphi = 100.0;
        }
        let err = drop_implausible(&mut degrees, |i| format!("row {}", i + 1)).unwrap_err();
        assert!(
            err.starts_with("column varphi: 200 of 200 rows")
                && err.contains("varphi = 100")
                && err.contains("not degrees"),
            "{err}"
        );
    }
}
