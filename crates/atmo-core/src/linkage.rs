//! The tilt linkage: lead-screw displacement x = |OA|, tilt angle varphi,
//! and motor encoder counts.
//!
//! From the paper, with the hinge angle theta of the first link:
//!
//! ```text
//! [Dx, Dy] = [h, x] + [[cos theta, cos varphi], [sin theta, -sin varphi]] [d1, d2]
//! ```
//!
//! Forward: `cos theta = (Dx - h - d2 cos varphi) / d1` on the branch
//! `theta in [0, pi]`, then `x = Dy - d1 sin theta + d2 sin varphi`. This is the
//! branch on which x grows monotonically with varphi (about -0.7 mm at 0 to
//! 97 mm at 90 deg for ATMO).
//!
//! Inverse: eliminating theta gives `b sin varphi - a cos varphi = K` with
//! `a = Dx - h`, `b = Dy - x`, `K = (d1^2 - a^2 - b^2 - d2^2) / (2 d2)`, i.e.
//! `varphi = psi + asin(K / r)`, `r = hypot(a, b)`, `psi = atan2(a, b)`.
//!
//! Encoder: zero at varphi = 0, `counts = (x - x(0)) / pitch * counts_per_rev`.

use crate::config::LinkageConfig;
use crate::error::{CoreError, Result};

/// Samples of the monotonicity check over the tilt range.
const MONOTONICITY_SAMPLES: usize = 2000;

/// Linkage geometry with its valid tilt range; all lengths in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linkage {
    h: f64,
    d1: f64,
    d2: f64,
    dx: f64,
    dy: f64,
    thread_pitch: f64,
    counts_per_rev: f64,
    tilt_max: f64,
    x_min: f64,
    x_max: f64,
}

impl Linkage {
    /// Builds the linkage and checks that it reaches every tilt in
    /// `[0, tilt_max]` with x strictly increasing.
    pub fn from_config(config: &LinkageConfig, tilt_max: f64) -> Result<Self> {
        let mut link = Self {
            h: config.h,
            d1: config.d1,
            d2: config.d2,
            dx: config.d[0],
            dy: config.d[1],
            thread_pitch: config.thread_pitch,
            counts_per_rev: config.counts_per_rev,
            tilt_max,
            x_min: f64::NEG_INFINITY,
            x_max: f64::INFINITY,
        };
        // Monotonicity over the whole range, sampled finely: the closed-form
        // inverse is only valid on a monotone branch.
        let mut previous = link.screw_unchecked(0.0)?;
        link.x_min = previous;
        for i in 1..=MONOTONICITY_SAMPLES {
            let varphi = tilt_max * i as f64 / MONOTONICITY_SAMPLES as f64;
            let x = link.screw_unchecked(varphi)?;
            if x <= previous {
                return Err(CoreError::OutOfRange {
                    quantity: "linkage: tilt where x(varphi) stops increasing",
                    value: varphi,
                    min: 0.0,
                    max: tilt_max,
                });
            }
            previous = x;
        }
        link.x_max = previous;
        Ok(link)
    }

    /// Valid tilt range, rad.
    pub fn tilt_range(&self) -> (f64, f64) {
        (0.0, self.tilt_max)
    }

    /// Valid screw displacement range, m.
    pub fn screw_range(&self) -> (f64, f64) {
        (self.x_min, self.x_max)
    }

    /// Valid encoder range (counts, continuous).
    pub fn counts_range(&self) -> (f64, f64) {
        (0.0, self.counts_from_screw_unchecked(self.x_max))
    }

    fn screw_unchecked(&self, varphi: f64) -> Result<f64> {
        let cos_theta = (self.dx - self.h - self.d2 * varphi.cos()) / self.d1;
        // ATMO's linkage reaches theta = 0 exactly at 90 deg: accept the
        // rounding of that singular end point.
        if cos_theta.is_nan() || cos_theta.abs() > 1.0 + 1e-12 {
            return Err(CoreError::OutOfRange {
                quantity: "linkage: cos(theta) at this tilt",
                value: cos_theta,
                min: -1.0,
                max: 1.0,
            });
        }
        let cos_theta = cos_theta.clamp(-1.0, 1.0);
        let sin_theta = (1.0 - cos_theta * cos_theta).sqrt();
        Ok(self.dy - self.d1 * sin_theta + self.d2 * varphi.sin())
    }

    /// Screw displacement x (m) at tilt `varphi` (rad).
    pub fn screw_from_tilt(&self, varphi: f64) -> Result<f64> {
        check("tilt varphi [rad]", varphi, 0.0, self.tilt_max)?;
        self.screw_unchecked(varphi.clamp(0.0, self.tilt_max))
    }

    /// Tilt `varphi` (rad) at screw displacement `x` (m).
    pub fn tilt_from_screw(&self, x: f64) -> Result<f64> {
        check("screw displacement x [m]", x, self.x_min, self.x_max)?;
        let a = self.dx - self.h;
        let b = self.dy - x;
        let k = (self.d1 * self.d1 - a * a - b * b - self.d2 * self.d2) / (2.0 * self.d2);
        let r = a.hypot(b);
        let varphi = a.atan2(b) + (k / r).clamp(-1.0, 1.0).asin();
        // Rounding at the ends of the range must not leave the valid interval.
        Ok(varphi.clamp(0.0, self.tilt_max))
    }

    fn counts_from_screw_unchecked(&self, x: f64) -> f64 {
        (x - self.x_min) / self.thread_pitch * self.counts_per_rev
    }

    /// Encoder counts (continuous; the encoder reports them rounded) at tilt `varphi`.
    pub fn counts_from_tilt(&self, varphi: f64) -> Result<f64> {
        Ok(self.counts_from_screw_unchecked(self.screw_from_tilt(varphi)?))
    }

    /// Tilt `varphi` (rad) from encoder counts.
    pub fn tilt_from_counts(&self, counts: f64) -> Result<f64> {
        let (lo, hi) = self.counts_range();
        check("encoder counts", counts, lo, hi)?;
        let x = self.x_min + counts / self.counts_per_rev * self.thread_pitch;
        self.tilt_from_screw(x.clamp(self.x_min, self.x_max))
    }
}

fn check(quantity: &'static str, value: f64, min: f64, max: f64) -> Result<()> {
    // A relative slack of 1e-12 absorbs the rounding of a value that was
    // computed at the end of the range.
    let slack = 1e-12 * (max - min).abs().max(1.0);
    if value.is_finite() && value >= min - slack && value <= max + slack {
        Ok(())
    } else {
        Err(CoreError::OutOfRange {
            quantity,
            value,
            min,
            max,
        })
    }
}
