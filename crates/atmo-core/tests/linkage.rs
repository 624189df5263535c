//! Linkage kinematics: round trips over the whole range, monotonicity and
//! out-of-range inputs.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use atmo_core::{CoreError, Linkage, RobotConfig};

fn linkage() -> Linkage {
    let cfg = RobotConfig::atmo();
    Linkage::from_config(&cfg.linkage, cfg.limits.tilt_max()).unwrap()
}

const STEPS: usize = 9000;

#[test]
fn tilt_screw_tilt_round_trip_is_exact() {
    let link = linkage();
    let (_, max) = link.tilt_range();
    for i in 0..=STEPS {
        let varphi = max * i as f64 / STEPS as f64;
        let x = link.screw_from_tilt(varphi).unwrap();
        let back = link.tilt_from_screw(x).unwrap();
        assert!((back - varphi).abs() < 1e-9, "varphi {varphi}: back {back}");
    }
}

#[test]
fn screw_tilt_screw_round_trip_is_exact() {
    let link = linkage();
    let (lo, hi) = link.screw_range();
    for i in 0..=STEPS {
        let x = lo + (hi - lo) * i as f64 / STEPS as f64;
        let varphi = link.tilt_from_screw(x).unwrap();
        let back = link.screw_from_tilt(varphi).unwrap();
        assert!((back - x).abs() < 1e-9, "x {x}: back {back}");
    }
}

#[test]
fn counts_round_trip_is_exact() {
    let link = linkage();
    let (_, max) = link.tilt_range();
    assert_eq!(link.counts_from_tilt(0.0).unwrap(), 0.0);
    for i in 0..=STEPS {
        let varphi = max * i as f64 / STEPS as f64;
        let counts = link.counts_from_tilt(varphi).unwrap();
        let back = link.tilt_from_counts(counts).unwrap();
        assert!(
            (back - varphi).abs() < 1e-9,
            "varphi {varphi}: counts {counts}, back {back}"
        );
    }
    // 0.8 cm per revolution, 1632.67 counts per revolution.
    let (_, counts_max) = link.counts_range();
    let (x_lo, x_hi) = link.screw_range();
    assert!((counts_max - (x_hi - x_lo) / 0.008 * 1632.67).abs() < 1e-6);
}

#[test]
fn screw_displacement_grows_monotonically_with_tilt() {
    let link = linkage();
    let (_, max) = link.tilt_range();
    let mut previous = f64::NEG_INFINITY;
    for i in 0..=STEPS {
        let x = link.screw_from_tilt(max * i as f64 / STEPS as f64).unwrap();
        assert!(x > previous);
        previous = x;
    }
    // The paper's geometry: about 9.8 cm of screw travel from quadrotor to car.
    let (lo, hi) = link.screw_range();
    assert!((hi - lo - 0.0977).abs() < 5e-4, "travel {}", hi - lo);
}

#[test]
fn out_of_range_inputs_are_errors_not_nan() {
    let link = linkage();
    let (x_lo, x_hi) = link.screw_range();
    let (_, c_hi) = link.counts_range();
    for bad in [-0.1, 1.7, f64::NAN, f64::INFINITY] {
        assert!(
            matches!(link.screw_from_tilt(bad), Err(CoreError::OutOfRange { .. })),
            "tilt {bad}"
        );
    }
    for bad in [x_lo - 1e-3, x_hi + 1e-3, f64::NAN] {
        assert!(
            matches!(link.tilt_from_screw(bad), Err(CoreError::OutOfRange { .. })),
            "screw {bad}"
        );
    }
    for bad in [-5.0, c_hi + 5.0, f64::NEG_INFINITY] {
        assert!(
            matches!(
                link.tilt_from_counts(bad),
                Err(CoreError::OutOfRange { .. })
            ),
            "counts {bad}"
        );
    }
    let msg = link.tilt_from_counts(-5.0).unwrap_err().to_string();
    assert!(msg.contains("encoder counts"), "{msg}");
}
