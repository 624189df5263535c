//! A bound on the rotors' mean thrust as a box, so that the condensed QP
//! keeps its exact homotopy feedback.
//!
//! `sum_i u_i <= 4 m` is a general inequality, not a bound. In the rotors'
//! modes, the orthogonal and symmetric Hadamard transform
//!
//! ```text
//! v = T u,   u = T v,   T = 1/2 [ 1  1  1  1
//!                                 1 -1  1 -1
//!                                 1  1 -1 -1
//!                                 1 -1 -1  1 ]
//! ```
//!
//! the mean is one coordinate, `v_0 = 2 mean(u)`, and `v_1..v_3` are the
//! three differential patterns (`u_i = mean(u) + 1/2 sum_k T_ik v_k`; which
//! pattern rolls, pitches or yaws depends on the rotor layout, and the box
//! treats them alike). The box
//!
//! ```text
//! 2 (lo + 3 delta / 2) <= v_0 <= 2 m,   |v_k| <= delta,   delta = 2 (hi - m) / 3
//! ```
//!
//! (`lo`, `hi`: the rotors' own bounds) keeps every rotor within
//! `[lo, hi]`, `|u_i - mean| <= 3 delta / 2 = hi - m`: it is the largest
//! box of equal differential bounds inside the polytope
//! `{lo <= u_i <= hi, mean(u) <= m}`. A rotor may thus take up to `hi - m`
//! more than the mean, and attitude control keeps its differential thrust
//! while the mean is at its bound, which per-rotor bounds at `m` take away
//! (every rotor saturated).
//!
//! The QP of a stage with the mean bounded is written in `v` (its Hessian
//! blocks `T H T`, its gradient `T g`); [`to_modes`] and [`from_modes`]
//! move one stage's rotor block between the two (they are the same map).

/// Rotors per stage: the first `ROTORS` inputs of a stage.
pub const ROTORS: usize = 4;

/// `T x` for the four rotor entries at `x[0..4]` (`T` is its own inverse).
#[inline]
pub fn to_modes(x: &mut [f64]) {
    let (a, b, c, d) = (x[0], x[1], x[2], x[3]);
    x[0] = 0.5 * (a + b + c + d);
    x[1] = 0.5 * (a - b + c - d);
    x[2] = 0.5 * (a + b - c - d);
    x[3] = 0.5 * (a - b - c + d);
}

/// `T v`: the rotors' commands from their modes.
#[inline]
pub fn from_modes(v: &mut [f64]) {
    to_modes(v);
}

/// The box of a stage's modes for the mean bound `mean_max` and the rotors'
/// own bounds `lo..hi`: `(v_lo, v_hi)`, see the module docs. An empty range
/// of the mean (`lo + (hi - mean_max) > mean_max`) collapses onto `mean_max`.
pub fn mode_box(lo: f64, hi: f64, mean_max: f64) -> ([f64; ROTORS], [f64; ROTORS]) {
    let excess = (hi - mean_max).max(0.0);
    let delta = 2.0 * excess / 3.0;
    let mean_min = (lo + excess).min(mean_max);
    (
        [2.0 * mean_min, -delta, -delta, -delta],
        [2.0 * mean_max, delta, delta, delta],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_transform_is_its_own_inverse_and_keeps_lengths() {
        let u = [0.9, 0.95, 1.0, 0.7];
        let mut v = u;
        to_modes(&mut v);
        assert!((v[0] - 2.0 * u.iter().sum::<f64>() / 4.0).abs() < 1e-12);
        let norm = |x: &[f64]| x.iter().map(|a| a * a).sum::<f64>();
        assert!((norm(&v) - norm(&u)).abs() < 1e-12);
        from_modes(&mut v);
        for (a, b) in u.iter().zip(&v) {
            assert!((a - b).abs() < 1e-12);
        }
    }

    #[test]
    fn every_corner_of_the_box_keeps_each_rotor_in_its_bounds_and_the_mean_under_its_bound() {
        let (lo, hi, m) = (0.0, 1.0, 0.95);
        let (v_lo, v_hi) = mode_box(lo, hi, m);
        let mut worst_hi: f64 = 0.0;
        for corner in 0..16 {
            let mut v = [0.0; ROTORS];
            for (k, x) in v.iter_mut().enumerate() {
                *x = if corner >> k & 1 == 1 {
                    v_hi[k]
                } else {
                    v_lo[k]
                };
            }
            from_modes(&mut v);
            let mean = v.iter().sum::<f64>() / 4.0;
            assert!(mean <= m + 1e-12, "mean {mean}");
            for u in v {
                assert!((lo - 1e-12..=hi + 1e-12).contains(&u), "rotor {u}");
                worst_hi = worst_hi.max(u);
            }
        }
        // The box is the largest of its kind: some corner reaches the rotor bound.
        assert!((worst_hi - hi).abs() < 1e-12);
    }
}
