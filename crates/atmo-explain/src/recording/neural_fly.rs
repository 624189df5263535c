//! Importer for the Neural-Fly flight logs (O'Connell et al., "Neural-Fly
//! enables rapid learning for agile flight in strong winds", Science
//! Robotics 7(66), 2022; aerorobotics/neural-fly, `data/experiment`).
//!
//! Their CSV has one row per ~50 Hz sample, vectors as JSON list literals in
//! quoted cells. The conventions, worked out from the data in
//! docs/neural_fly.md (`scripts/neural_fly_conventions.py`):
//!
//! - world frame z-up (`p`, `v`), body frame FLU: `R` (row-major) is body to
//!   world and `w` the body rates in that frame (`vee(R^T dR/dt)` matches
//!   `w`); `q` is `(x, y, z, w)` of the same rotation (unused here).
//! - motors in PX4 quad-x positions (1 front-right, 2 back-left,
//!   3 front-left, 4 back-right), the project's order.
//!
//! Conversion to the recording format (NED / FRD): the half turn about x,
//! `F = diag(1, -1, -1)`, maps z-up to z-down and FLU to FRD:
//! `p' = F p`, `v' = F v`, `R' = F R F`, `w' = F w`; Euler ZYX from `R'`.
//! Commands `u_i = pwm_i / PWM_FULL_SCALE` (the thrust is not linear in
//! it: docs/neural_fly.md); tilt 0; the ground plane at their z = 0.

use std::path::{Path, PathBuf};

use atmo_core::model::{Input, State, idx};
use nalgebra::Matrix3;

use crate::ExplainError;
use crate::recording::{Recording, Sample};

/// PWM that maps to the normalized command 1.
pub const PWM_FULL_SCALE: f64 = 2000.0;
/// Largest deviation of a row's `R` from a rotation: every entry of
/// `R^T R - I` and `det R - 1` within it (the logs' `R` are rotations to
/// about 1e-6; an all-zero `R`, a reflection or `1000 I` are far outside).
pub const ROTATION_TOLERANCE: f64 = 1e-2;
/// Columns the importer reads.
pub const NEURAL_FLY_COLUMNS: [&str; 6] = ["t", "p", "v", "R", "w", "pwm"];

/// Whether a header line is a Neural-Fly log's (it names `fa` and `pwm`
/// and the rotation `R`, and has no `x` column).
pub fn is_neural_fly_header(header: &str) -> bool {
    let names = split_row(header.trim_start_matches('\u{feff}'));
    let has = |c: &str| names.iter().any(|n| n.trim() == c);
    has("fa") && has("pwm") && has("R") && !has("x")
}

/// Splits one CSV row at the commas outside double quotes (their vector
/// cells are quoted list literals with commas inside).
pub fn split_row(line: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut start = 0;
    let mut quoted = false;
    for (i, c) in line.char_indices() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => {
                out.push(line[start..i].trim().trim_matches('"'));
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(line[start..].trim().trim_matches('"'));
    out
}

/// A cell: a number or a (nested) list of numbers, flattened row-major.
fn parse_cell(cell: &str, len: usize) -> Option<Vec<f64>> {
    let values: Vec<f64> = if cell.starts_with('[') {
        let v: serde_json::Value = serde_json::from_str(cell).ok()?;
        let mut flat = Vec::with_capacity(len);
        flatten(&v, &mut flat)?;
        flat
    } else {
        vec![cell.parse().ok()?]
    };
    (values.len() == len && values.iter().all(|v| v.is_finite())).then_some(values)
}

fn flatten(v: &serde_json::Value, out: &mut Vec<f64>) -> Option<()> {
    match v {
        serde_json::Value::Array(items) => items.iter().try_for_each(|i| flatten(i, out)),
        serde_json::Value::Number(n) => {
            out.push(n.as_f64()?);
            Some(())
        }
        _ => None,
    }
}

/// Whether the row-major 3x3 `r` is a rotation within
/// [`ROTATION_TOLERANCE`]: orthonormal with determinant +1.
pub fn is_rotation(r: &[f64]) -> bool {
    let m = Matrix3::from_row_slice(r);
    let defect = (m.transpose() * m - Matrix3::identity()).abs().max();
    defect <= ROTATION_TOLERANCE && (m.determinant() - 1.0).abs() <= ROTATION_TOLERANCE
}

/// Euler ZYX (yaw, pitch, roll) of a body-to-world rotation.
fn euler_zyx(r: &Matrix3<f64>) -> (f64, f64, f64) {
    let yaw = r[(1, 0)].atan2(r[(0, 0)]);
    let pitch = (-r[(2, 0)]).clamp(-1.0, 1.0).asin();
    let roll = r[(2, 1)].atan2(r[(2, 2)]);
    (yaw, pitch, roll)
}

/// One Neural-Fly row (cells already parsed) in the recording's conventions.
fn convert(t: f64, p: &[f64], v: &[f64], r: &[f64], w: &[f64], pwm: &[f64]) -> Sample {
    let flip = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, -1.0, -1.0));
    let r_ned = flip * Matrix3::from_row_slice(r) * flip;
    let (yaw, pitch, roll) = euler_zyx(&r_ned);
    let mut x = State::zeros();
    x[idx::X] = p[0];
    x[idx::Y] = -p[1];
    x[idx::Z] = -p[2];
    x[idx::YAW] = yaw;
    x[idx::PITCH] = pitch;
    x[idx::ROLL] = roll;
    x[idx::VX] = v[0];
    x[idx::VY] = -v[1];
    x[idx::VZ] = -v[2];
    x[idx::WX] = w[0];
    x[idx::WY] = -w[1];
    x[idx::WZ] = -w[2];
    let u = Input::from_iterator(pwm.iter().map(|p| p / PWM_FULL_SCALE));
    Sample {
        t,
        x,
        u,
        applied: u,
        varphi: 0.0,
        ground_z: 0.0,
        battery_v: None,
    }
}

/// Reads a Neural-Fly log (see the module docs for the conversion). Rows
/// with a missing, malformed or non-finite cell are skipped and counted, as
/// are rows whose `R` is not a rotation ([`is_rotation`]); then the reader
/// contract ([`super::contract::finish`]: time base, ranges). Other columns
/// are listed as ignored.
pub fn from_neural_fly_str(
    text: &str,
    file: impl Into<PathBuf>,
) -> Result<Recording, ExplainError> {
    let file = file.into();
    let fail = |message: String| ExplainError::Input {
        file: file.clone(),
        message,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines
        .next()
        .ok_or_else(|| fail("the file is empty (expected a Neural-Fly header row)".into()))?;
    let names = split_row(header.trim_start_matches('\u{feff}'));
    let find = |c: &str| names.iter().position(|n| *n == c);
    let missing: Vec<&str> = NEURAL_FLY_COLUMNS
        .iter()
        .copied()
        .filter(|c| find(c).is_none())
        .collect();
    if !missing.is_empty() {
        return Err(fail(format!(
            "Neural-Fly log without column(s) {} (header has: {})",
            missing.join(", "),
            names.join(", ")
        )));
    }
    let cols: Vec<usize> = NEURAL_FLY_COLUMNS
        .iter()
        .map(|c| find(c).unwrap_or(0))
        .collect();
    let mut rec = Recording {
        source: file.clone(),
        ignored_columns: names
            .iter()
            .filter(|n| !n.is_empty() && !NEURAL_FLY_COLUMNS.contains(n))
            .map(|n| (*n).to_string())
            .collect(),
        at_unit: "line",
        ..Recording::default()
    };
    for (index, line) in lines {
        let cells = split_row(line);
        let cell = |k: usize, len: usize| cells.get(cols[k]).and_then(|c| parse_cell(c, len));
        let (Some(t), Some(p), Some(v), Some(r), Some(w), Some(pwm)) = (
            cell(0, 1),
            cell(1, 3),
            cell(2, 3),
            cell(3, 9),
            cell(4, 3),
            cell(5, 4),
        ) else {
            rec.skipped_nonfinite += 1;
            continue;
        };
        if !is_rotation(&r) {
            rec.skipped_rotation += 1;
            continue;
        }
        if rec.samples.len() == super::MAX_ROWS {
            return Err(fail(super::row_limit_error(&format!("line {}", index + 1))));
        }
        rec.at.push(index + 1);
        rec.samples.push(convert(t[0], &p, &v, &r, &w, &pwm));
    }
    super::contract::finish(&mut rec).map_err(&fail)?;
    Ok(rec)
}

/// Reads a Neural-Fly log from a file.
pub fn load_neural_fly(path: &Path) -> Result<Recording, ExplainError> {
    let fail = |message: String| ExplainError::Input {
        file: path.to_path_buf(),
        message,
    };
    let bytes = super::contract::read_input(path).map_err(&fail)?;
    super::contract::check_text(&bytes).map_err(&fail)?;
    let text = String::from_utf8(bytes)
        .map_err(|e| fail(format!("not UTF-8 text: {}", e.utf8_error())))?;
    from_neural_fly_str(&text, path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use atmo_core::model::rotation;

    const HEADER: &str = ",t,p,p_d,v,v_d,q,R,w,T_sp,q_sp,hover_throttle,fa,pwm";

    fn row(i: usize, t: f64, r: &str) -> String {
        format!(
            "{i},{t},\"[0.3, -0.04, 2.2]\",\"[0.25, 0.0, 2.15]\",\"[-0.07, 0.006, -0.05]\",\
             \"[0.0, 0.0, 0.0]\",\"[0.0, 0.0, 0.0, 1.0]\",\"{r}\",\"[0.01, 0.02, 0.03]\",[0.49],\
             \"[0.0, 0.0, 0.0, 1.0]\",[0.48],\"[0.3, -0.3, -0.4]\",\"[1000.0, 1100.0, 950.0, 1050.0]\""
        )
    }

    #[test]
    fn converts_frames_and_commands() {
        // FLU body rolled +0.1 rad about x (right wing up in z-up terms):
        // in FRD / NED the roll is also +0.1 (the half turn about x keeps
        // rotations about x), the pitch and yaw change sign.
        let (s, c) = 0.1f64.sin_cos();
        let r = format!("[[1.0, 0.0, 0.0], [0.0, {c}, {}], [0.0, {s}, {c}]]", -s);
        let text = format!("{HEADER}\n{}\n{}\n", row(0, 0.0, &r), row(1, 0.02, &r));
        assert!(is_neural_fly_header(HEADER));
        let rec = from_neural_fly_str(&text, "t.csv").unwrap();
        assert_eq!(rec.samples.len(), 2);
        let x = rec.samples[0].x;
        assert!((x[idx::Z] + 2.2).abs() < 1e-12 && (x[idx::Y] - 0.04).abs() < 1e-12);
        assert!((x[idx::VZ] - 0.05).abs() < 1e-12);
        assert!((x[idx::ROLL] - 0.1).abs() < 1e-12, "roll {}", x[idx::ROLL]);
        assert!(x[idx::PITCH].abs() < 1e-12 && x[idx::YAW].abs() < 1e-12);
        assert!((x[idx::WY] + 0.02).abs() < 1e-12 && (x[idx::WZ] + 0.03).abs() < 1e-12);
        let ned = rotation(x[idx::YAW], x[idx::PITCH], x[idx::ROLL]);
        assert!((ned[(2, 1)] - s).abs() < 1e-12);
        assert!((rec.samples[0].u[1] - 0.55).abs() < 1e-12);
        assert!(rec.ignored_columns.contains(&"fa".to_string()));
    }

    #[test]
    fn bad_rows_are_counted() {
        let r = "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]";
        let bad = row(1, 0.02, "[[1.0, 0.0], [0.0, 1.0]]");
        let text = format!(
            "{HEADER}\n{}\n{bad}\n{}\n{}\n",
            row(0, 0.0, r),
            row(2, 0.0, r),
            row(3, 0.04, r)
        );
        let rec = from_neural_fly_str(&text, "t.csv").unwrap();
        assert_eq!(
            (rec.samples.len(), rec.skipped_nonfinite, rec.skipped_time),
            (2, 1, 1)
        );
        let err = from_neural_fly_str(",t,p\n0,0.0,\"[1,2,3]\"\n", "t.csv").unwrap_err();
        assert!(err.to_string().contains("v, R, w, pwm"), "{err}");
    }
}
