//! The recorded velocity's slow errors, corrected from the positions.
//!
//! A velocity estimate can drift where positions do not: an EKF's bias
//! wander, a motion-capture system's filtered velocity, the independent
//! generator's Gauss-Markov error (0.004 m/s, 0.1 s). The finder
//! differentiates the velocity, so such a drift reads as a force, and the
//! regressors built from it carry it too. On the generator's drag + wind
//! flight it made the axial drag and the vertical body area look separable
//! when the flight cannot tell them apart (docs/explain.md, "Limits"). So
//! below `f_c` the velocity is taken from the
//! positions:
//!
//! ```text
//! v_f = v + LP( D (p - I v) )
//! ```
//!
//! with `I v` the trapezoid integral of the recorded velocity on the rows'
//! own times (so uneven row spacing cancels: `p - I v` is constant for a
//! velocity that is the positions' derivative), `D` the Savitzky-Golay
//! derivative the finder differentiates with, and `LP` a second-order
//! Butterworth low-pass run forward and backward (zero phase,
//! `|H|^2 = 1 / (1 + (f / f_c)^4)`). Above `f_c` the recorded velocity is
//! kept: there, differentiating positions twice would amplify their noise.
//!
//! The correction is applied along each stretch of rows without a time gap
//! (as the finder's runs are split), and only when the positions and the
//! velocity agree as a velocity sensor's drift can make them
//! ([`MAX_CORRECTION_RMS`]): a recording whose positions are in another
//! frame, or jump, keeps its velocity, and the report says why.

use std::borrow::Cow;

use atmo_core::model::idx;

use crate::data::{half_window, sg_derivative_taps};
use crate::recording::Recording;

/// Hz: below this the velocity comes from the positions. The finder's
/// differentiator (a 0.1 s window) passes up to about 10 Hz; 3 Hz keeps
/// the positions' doubly differentiated noise out and takes the drift of a
/// velocity estimate (whose correlation times are 0.05 s and longer) out.
pub const FROM_POSITIONS_BELOW_HZ: f64 = 3.0;

/// m/s: the largest RMS correction (any axis) that counts as a velocity
/// sensor's drift. Beyond it the two columns disagree about the motion.
pub const MAX_CORRECTION_RMS: f64 = 0.1;

/// What the correction did (reported).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct VelocityCorrection {
    /// The corrected velocity replaced the recorded one.
    pub applied: bool,
    /// Hz.
    pub below_hz: f64,
    /// RMS of the correction per world axis (m/s), over the corrected rows.
    pub rms: [f64; 3],
}

/// The recording with its velocity's band below [`FROM_POSITIONS_BELOW_HZ`]
/// taken from its positions (see the module docs), and what that changed;
/// the recording itself (not a copy) when the correction is not applied.
pub fn from_positions(rec: &Recording) -> (Cow<'_, Recording>, VelocityCorrection) {
    let samples = &rec.samples;
    let dt = rec.median_dt();
    let mut report = VelocityCorrection {
        below_hz: FROM_POSITIONS_BELOW_HZ,
        ..VelocityCorrection::default()
    };
    if !dt.is_finite() || dt <= 0.0 || samples.len() < 3 {
        return (Cow::Borrowed(rec), report);
    }
    let half = half_window(dt);
    let taps = sg_derivative_taps(half, dt);
    let low_pass = Butterworth2::low_pass(FROM_POSITIONS_BELOW_HZ, dt);
    let mut correction = vec![[0.0; 3]; samples.len()];
    let mut sum_sq = [0.0; 3];
    let mut rows = 0usize;
    for (s, e) in stretches(rec, 2.0 * dt) {
        let len = e - s;
        if len < 2 * half + 1 {
            continue;
        }
        // Positions minus the integral of the velocity.
        let mut drift = Vec::with_capacity(len);
        let mut integral = [0.0; 3];
        for k in s..e {
            if k > s {
                let h = samples[k].t - samples[k - 1].t;
                for c in 0..3 {
                    integral[c] +=
                        0.5 * h * (samples[k].x[idx::VX + c] + samples[k - 1].x[idx::VX + c]);
                }
            }
            let p = &samples[k].x;
            drift.push([
                p[idx::X] - integral[0],
                p[idx::Y] - integral[1],
                p[idx::Z] - integral[2],
            ]);
        }
        // Its derivative inside the window's reach, held at the ends.
        let mut band = vec![[0.0; 3]; len];
        for j in half..len - half {
            for (q, tap) in taps.iter().enumerate() {
                for c in 0..3 {
                    band[j][c] += tap * drift[j + q - half][c];
                }
            }
        }
        for j in 0..half {
            band[j] = band[half];
            band[len - 1 - j] = band[len - 1 - half];
        }
        for c in 0..3 {
            let mut axis: Vec<f64> = band.iter().map(|b| b[c]).collect();
            low_pass.zero_phase(&mut axis);
            for (j, v) in axis.into_iter().enumerate() {
                correction[s + j][c] = v;
                sum_sq[c] += v * v;
            }
        }
        rows += len;
    }
    if rows == 0 {
        return (Cow::Borrowed(rec), report);
    }
    report.rms = sum_sq.map(|s| (s / rows as f64).sqrt());
    // NaN (a non-finite cell in a position) counts as disagreement.
    if !report
        .rms
        .iter()
        .all(|r| r.is_finite() && *r <= MAX_CORRECTION_RMS)
    {
        return (Cow::Borrowed(rec), report);
    }
    report.applied = true;
    let mut out = rec.clone();
    for (sample, dv) in out.samples.iter_mut().zip(&correction) {
        for c in 0..3 {
            sample.x[idx::VX + c] += dv[c];
        }
    }
    (Cow::Owned(out), report)
}

/// Rows `[start, end)` without a time step above `gap`.
fn stretches(rec: &Recording, gap: f64) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for k in 1..rec.samples.len() {
        if rec.samples[k].t - rec.samples[k - 1].t > gap {
            out.push((start, k));
            start = k;
        }
    }
    out.push((start, rec.samples.len()));
    out
}

/// A second-order Butterworth section (bilinear transform, the RBJ
/// cookbook's low-pass with `Q = 1/sqrt 2`).
#[derive(Debug, Clone, Copy)]
struct Butterworth2 {
    b: [f64; 3],
    a: [f64; 2],
}

impl Butterworth2 {
    fn low_pass(cutoff_hz: f64, dt: f64) -> Self {
        let w0 = 2.0 * std::f64::consts::PI * (cutoff_hz * dt).min(0.45);
        let alpha = w0.sin() * std::f64::consts::FRAC_1_SQRT_2;
        let a0 = 1.0 + alpha;
        let k = (1.0 - w0.cos()) / a0;
        Self {
            b: [0.5 * k, k, 0.5 * k],
            a: [-2.0 * w0.cos() / a0, (1.0 - alpha) / a0],
        }
    }

    /// One pass, started in steady state at the first value.
    fn pass(&self, xs: &mut [f64]) {
        let Some(&x0) = xs.first() else { return };
        let (mut x1, mut x2, mut y1, mut y2) = (x0, x0, x0, x0);
        for v in xs.iter_mut() {
            let x = *v;
            let y =
                self.b[0] * x + self.b[1] * x1 + self.b[2] * x2 - self.a[0] * y1 - self.a[1] * y2;
            (x2, x1, y2, y1) = (x1, x, y1, y);
            *v = y;
        }
    }

    /// Forward, then backward: zero phase, the magnitude squared.
    fn zero_phase(&self, xs: &mut [f64]) {
        self.pass(xs);
        xs.reverse();
        self.pass(xs);
        xs.reverse();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::Sample;
    use atmo_core::model::{Input, State};

    fn recording(rows: &[(f64, f64, f64)]) -> Recording {
        let samples = rows
            .iter()
            .map(|&(t, x, vx)| {
                let mut s = State::zeros();
                s[idx::X] = x;
                s[idx::VX] = vx;
                Sample {
                    t,
                    x: s,
                    u: Input::zeros(),
                    applied: Input::zeros(),
                    varphi: 0.0,
                    ground_z: 0.0,
                    battery_v: None,
                }
            })
            .collect();
        Recording::from_samples("test", samples)
    }

    /// Uneven rows (8 and 9 ms, as the plant's 120 Hz motion capture lands
    /// on 1 ms steps) of a consistent motion: nothing to correct.
    #[test]
    fn a_velocity_that_is_the_positions_derivative_is_kept() {
        let mut t: f64 = 0.0;
        let rows: Vec<_> = (0..3000)
            .map(|k| {
                let row = (t, (2.0 * t).sin(), 2.0 * (2.0 * t).cos());
                t += if k % 3 == 2 { 0.009 } else { 0.008 };
                row
            })
            .collect();
        let rec = recording(&rows);
        let (out, c) = from_positions(&rec);
        assert!(c.applied);
        assert!(c.rms[0] < 1e-4, "{c:?}");
        for (a, b) in out.samples.iter().zip(&recording(&rows).samples) {
            assert!((a.x[idx::VX] - b.x[idx::VX]).abs() < 5e-4);
        }
    }

    /// A slow drift on the velocity (0.02 m/s at 0.5 Hz) is taken out; a
    /// fast one (20 Hz) is left.
    #[test]
    fn a_slow_velocity_drift_is_taken_out_and_a_fast_one_kept() {
        let dt = 1.0 / 150.0;
        let truth = |t: f64| (2.0 * (1.5 * t).cos() * 1.5, 2.0 * (1.5 * t).sin());
        let drift = |t: f64, f: f64| 0.02 * (2.0 * std::f64::consts::PI * f * t).sin();
        for (f, kept) in [(0.5, false), (20.0, true)] {
            let rows: Vec<_> = (0..6000)
                .map(|k| {
                    let t = f64::from(k) * dt;
                    let (v, x) = truth(t);
                    (t, x, v + drift(t, f))
                })
                .collect();
            let rec = recording(&rows);
            let (out, c) = from_positions(&rec);
            assert!(c.applied);
            let mut worst: f64 = 0.0;
            for s in out.samples.iter().skip(300).take(5400) {
                let t = s.t;
                let left = s.x[idx::VX] - truth(t).0;
                let expected = if kept { drift(t, f) } else { 0.0 };
                worst = worst.max((left - expected).abs());
            }
            assert!(worst < 0.002, "drift at {f} Hz: off by {worst} m/s");
        }
    }

    /// Positions in another frame than the velocity: not a drift, kept as
    /// recorded.
    #[test]
    fn positions_that_disagree_with_the_velocity_leave_it_as_recorded() {
        let dt = 1.0 / 150.0;
        let rows: Vec<_> = (0..3000)
            .map(|k| {
                let t = f64::from(k) * dt;
                (t, -(1.5 * t).sin(), 1.5 * (1.5 * t).cos())
            })
            .collect();
        let rec = recording(&rows);
        let (out, c) = from_positions(&rec);
        assert!(!c.applied, "{c:?}");
        assert!(c.rms[0] > MAX_CORRECTION_RMS);
        assert!(matches!(out, Cow::Borrowed(_)), "not copied");
        assert_eq!(*out, rec);
    }
}
