//! Tilt calibration: encoder counts of the tilt board to the tilt angle
//! varphi, and back.
//!
//! Two calibrations:
//!
//! - a measured table of (counts, angle) points, interpolated linearly
//!   between points and held at its end values outside them (what the
//!   authors do with `numpy.interp`). The points must have strictly
//!   increasing counts and strictly monotonic angles (so that the table can
//!   be inverted for the velocity command) within 0..=90 deg;
//! - the linkage model of atmo-core: the board's counts are the model's
//!   counts, shifted so that the board reads 0 at the home switch and
//!   signed by `encoder_sign`.
//!
//! In both, the tilt driver publishes the linkage model's counts (the
//! daemon's convention: zero at varphi = 0, growing with varphi) so that the
//! daemon reads the tilt the table measured.

use atmo_core::Linkage;
use atmo_core::config_file::Checker;

use crate::error::{Result, RoboclawError};

/// The authors' measured table (mandralis/ATMO,
/// `atmo_ws/src/atmo/atmo/tilt_controller_hardware.py`, `encoder_data` and
/// `angle_data`): board counts of M2 (0 at the home switch, drive
/// configuration) against the tilt in degrees. Also in
/// `config/drivers/tilt.toml`.
pub const AUTHORS_TABLE_COUNTS: [f64; 27] = [
    0.0, 3696.0, 5551.0, 7647.0, 8886.0, 10118.0, 11062.0, 11982.0, 12846.0, 13957.0, 14885.0,
    15629.0, 16549.0, 17037.0, 17749.0, 19029.0, 19645.0, 20989.0, 21453.0, 22357.0, 22989.0,
    23517.0, 24013.0, 24605.0, 25437.0, 25973.0, 26325.0,
];
/// Tilt in degrees at each of [`AUTHORS_TABLE_COUNTS`].
pub const AUTHORS_TABLE_TILT_DEG: [f64; 27] = [
    90.0, 86.6, 84.0, 78.6, 74.2, 70.5, 66.5, 63.5, 59.7, 55.3, 51.3, 48.0, 44.2, 41.8, 38.4, 32.8,
    30.0, 24.2, 22.0, 18.0, 14.8, 12.9, 10.8, 8.2, 4.7, 2.8, 0.8,
];

/// A validated counts-to-tilt table (angles in rad).
#[derive(Debug, Clone, PartialEq)]
pub struct TiltTable {
    counts: Vec<f64>,
    tilt: Vec<f64>,
}

impl TiltTable {
    /// Checks and builds the table; errors name `file` and the keys
    /// `{prefix}table_counts` / `{prefix}table_tilt_deg` with the index.
    pub fn new(
        counts: &[f64],
        tilt_deg: &[f64],
        file: &std::path::Path,
        prefix: &str,
    ) -> Result<Self> {
        let c = Checker::new(file);
        let key_counts = format!("{prefix}table_counts");
        let key_tilt = format!("{prefix}table_tilt_deg");
        if counts.len() < 2 {
            return Err(c
                .fail(&key_counts, "at least 2 points", counts.len())
                .into());
        }
        if tilt_deg.len() != counts.len() {
            return Err(c
                .fail(
                    &key_tilt,
                    format!("as many points as {key_counts} ({})", counts.len()),
                    tilt_deg.len(),
                )
                .into());
        }
        for (i, v) in counts.iter().enumerate() {
            c.range(&format!("{key_counts}[{i}]"), *v, -1.0e9..=1.0e9, "counts")?;
            if i > 0 && *v <= counts[i - 1] {
                return Err(c
                    .fail(
                        &format!("{key_counts}[{i}]"),
                        format!("strictly increasing counts, > {}", counts[i - 1]),
                        v,
                    )
                    .into());
            }
        }
        let rising = tilt_deg[1] > tilt_deg[0];
        for (i, v) in tilt_deg.iter().enumerate() {
            c.range(&format!("{key_tilt}[{i}]"), *v, 0.0..=90.0, "deg")?;
            if i > 0 && (*v == tilt_deg[i - 1] || (*v > tilt_deg[i - 1]) != rising) {
                return Err(c
                    .fail(
                        &format!("{key_tilt}[{i}]"),
                        format!(
                            "strictly monotonic angles ({} from the first two points), after {}",
                            if rising { "rising" } else { "falling" },
                            tilt_deg[i - 1]
                        ),
                        v,
                    )
                    .into());
            }
        }
        Ok(Self {
            counts: counts.to_vec(),
            tilt: tilt_deg.iter().map(|d| d.to_radians()).collect(),
        })
    }

    /// The authors' table.
    pub fn authors() -> Self {
        Self {
            counts: AUTHORS_TABLE_COUNTS.to_vec(),
            tilt: AUTHORS_TABLE_TILT_DEG
                .iter()
                .map(|d| d.to_radians())
                .collect(),
        }
    }

    /// Index `i` of the segment `[i, i+1]` holding `x` in the sorted
    /// `xs` (clamped to the first and last segment).
    fn segment(xs: &[f64], x: f64, ascending: bool) -> usize {
        let last = xs.len().saturating_sub(2);
        let mut i = 0;
        while i < last
            && if ascending {
                x > xs[i + 1]
            } else {
                x < xs[i + 1]
            }
        {
            i += 1;
        }
        i
    }

    /// Tilt (rad) at board `counts`; outside the table, the end value
    /// (second: whether it was outside).
    pub fn tilt_from_counts(&self, counts: f64) -> (f64, bool) {
        let n = self.counts.len();
        if !counts.is_finite() || counts <= self.counts[0] {
            return (self.tilt[0], counts < self.counts[0] || !counts.is_finite());
        }
        if counts >= self.counts[n - 1] {
            return (self.tilt[n - 1], counts > self.counts[n - 1]);
        }
        let i = Self::segment(&self.counts, counts, true);
        let t = (counts - self.counts[i]) / (self.counts[i + 1] - self.counts[i]);
        (self.tilt[i] + t * (self.tilt[i + 1] - self.tilt[i]), false)
    }

    fn rising(&self) -> bool {
        self.tilt[1] > self.tilt[0]
    }

    /// Board counts at tilt `varphi` (rad), clamped to the table's ends.
    pub fn counts_from_tilt(&self, varphi: f64) -> f64 {
        let i = Self::segment(&self.tilt, varphi, self.rising());
        let (t0, t1) = (self.tilt[i], self.tilt[i + 1]);
        let t = ((varphi - t0) / (t1 - t0)).clamp(0.0, 1.0);
        self.counts[i] + t * (self.counts[i + 1] - self.counts[i])
    }

    /// d counts / d varphi (counts/rad) at tilt `varphi`: the slope of the
    /// segment holding it (the end segments outside the table).
    pub fn counts_per_rad(&self, varphi: f64) -> f64 {
        let i = Self::segment(&self.tilt, varphi, self.rising());
        (self.counts[i + 1] - self.counts[i]) / (self.tilt[i + 1] - self.tilt[i])
    }

    /// Tilt range covered (rad): (min, max).
    pub fn tilt_range(&self) -> (f64, f64) {
        let (a, b) = (self.tilt[0], self.tilt[self.tilt.len() - 1]);
        (a.min(b), a.max(b))
    }

    /// The measured points: (board counts, tilt rad).
    pub fn points(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.counts.iter().copied().zip(self.tilt.iter().copied())
    }

    /// How far the table and the linkage model disagree, point by point,
    /// if the board's counter were the model's encoder: board counts =
    /// `sign` x (model counts - model counts at `home_tilt`).
    pub fn compare_with_linkage(
        &self,
        linkage: &Linkage,
        sign: f64,
        home_tilt: f64,
    ) -> std::result::Result<LinkageComparison, RoboclawError> {
        let (_, tilt_max) = linkage.tilt_range();
        let (lo, hi) = linkage.counts_range();
        let home = linkage.counts_from_tilt(home_tilt.clamp(0.0, tilt_max))?;
        let mut points = Vec::with_capacity(self.counts.len());
        for (counts, table_tilt) in self.points() {
            let model = home + counts / sign;
            let model_tilt = if (lo..=hi).contains(&model) {
                Some(linkage.tilt_from_counts(model)?)
            } else {
                None
            };
            points.push(ComparedPoint {
                counts,
                table_tilt,
                model_tilt,
            });
        }
        Ok(LinkageComparison { points })
    }
}

/// One table point against the linkage model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ComparedPoint {
    /// Board counts of the point.
    pub counts: f64,
    /// The table's tilt there, rad.
    pub table_tilt: f64,
    /// The model's tilt at those counts, rad (`None`: beyond its range).
    pub model_tilt: Option<f64>,
}

/// The table against the linkage model ([`TiltTable::compare_with_linkage`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LinkageComparison {
    pub points: Vec<ComparedPoint>,
}

impl LinkageComparison {
    /// Largest |table - model| over the points the model reaches (rad), and
    /// the board counts where it is.
    pub fn max_abs(&self) -> Option<(f64, f64)> {
        self.points
            .iter()
            .filter_map(|p| p.model_tilt.map(|m| ((p.table_tilt - m).abs(), p.counts)))
            .fold(None, |best: Option<(f64, f64)>, x| match best {
                Some(b) if b.0 >= x.0 => Some(b),
                _ => Some(x),
            })
    }

    /// Points beyond the model's counts range.
    pub fn beyond_model(&self) -> usize {
        self.points
            .iter()
            .filter(|p| p.model_tilt.is_none())
            .count()
    }
}

/// How board counts become a tilt.
#[derive(Debug, Clone)]
pub enum Calibration {
    Table(TiltTable),
    /// Board counts = `sign` x (model counts - model counts at home).
    Linkage {
        sign: f64,
        home_counts: f64,
    },
}

/// The tilt board's counts against the daemon's convention.
#[derive(Debug, Clone)]
pub struct TiltCalibration {
    calibration: Calibration,
    linkage: Linkage,
    tilt_max: f64,
}

/// One encoder reading, converted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltReading {
    /// varphi, rad.
    pub tilt: f64,
    /// The linkage model's counts at that tilt (what the daemon reads).
    pub model_counts: f64,
    /// The reading was outside the table (held at its end).
    pub outside: bool,
}

impl TiltCalibration {
    /// `home_tilt` (rad): the tilt at the home switch (board count 0) for
    /// the linkage calibration.
    pub fn new(
        calibration: Calibration,
        linkage: Linkage,
        home_tilt: f64,
    ) -> std::result::Result<Self, RoboclawError> {
        let (_, tilt_max) = linkage.tilt_range();
        let calibration = match calibration {
            Calibration::Linkage { sign, .. } => Calibration::Linkage {
                sign,
                home_counts: linkage.counts_from_tilt(home_tilt.clamp(0.0, tilt_max))?,
            },
            table @ Calibration::Table(_) => table,
        };
        Ok(Self {
            calibration,
            linkage,
            tilt_max,
        })
    }

    /// Converts board `counts`.
    pub fn read(&self, counts: f64) -> TiltReading {
        let (tilt, outside, model_counts) = match &self.calibration {
            Calibration::Table(table) => {
                let (tilt, outside) = table.tilt_from_counts(counts);
                let tilt = tilt.clamp(0.0, self.tilt_max);
                (tilt, outside, self.model_counts(tilt))
            }
            Calibration::Linkage { sign, home_counts } => {
                let model = home_counts + counts / sign;
                let (lo, hi) = self.linkage.counts_range();
                let clamped = model.clamp(lo, hi);
                let tilt = self.linkage.tilt_from_counts(clamped).unwrap_or(0.0);
                (tilt, clamped != model, clamped)
            }
        };
        TiltReading {
            tilt,
            model_counts,
            outside,
        }
    }

    fn model_counts(&self, tilt: f64) -> f64 {
        self.linkage
            .counts_from_tilt(tilt.clamp(0.0, self.tilt_max))
            .unwrap_or(0.0)
    }

    /// The board's counts at `tilt` (rad): the inverse of [`Self::read`]
    /// inside the calibrated range (a table holds its end values outside
    /// it). A simulation that owns the mechanism sets the board's counter
    /// with it.
    pub fn board_counts(&self, tilt: f64) -> f64 {
        match &self.calibration {
            Calibration::Table(table) => table.counts_from_tilt(tilt),
            Calibration::Linkage { sign, home_counts } => {
                (self.model_counts(tilt) - home_counts) * sign
            }
        }
    }

    /// Board counts per rad of tilt at `tilt` (signed).
    pub fn counts_per_rad(&self, tilt: f64) -> f64 {
        match &self.calibration {
            Calibration::Table(table) => table.counts_per_rad(tilt),
            Calibration::Linkage { sign, .. } => {
                // Central difference inside the valid range: the model's
                // derivative is smooth and this runs once a tick.
                let h = 1e-4;
                let a = (tilt - h).clamp(0.0, self.tilt_max);
                let b = (tilt + h).clamp(0.0, self.tilt_max);
                if b <= a {
                    return 0.0;
                }
                sign * (self.model_counts(b) - self.model_counts(a)) / (b - a)
            }
        }
    }

    /// Tilt range the calibration covers (rad).
    pub fn tilt_range(&self) -> (f64, f64) {
        match &self.calibration {
            Calibration::Table(table) => table.tilt_range(),
            Calibration::Linkage { .. } => (0.0, self.tilt_max),
        }
    }
}
