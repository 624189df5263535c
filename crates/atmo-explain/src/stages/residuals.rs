//! Stage 1, residuals: the recording through the nominal model (see
//! [`crate::data`]) and its cut into cross-validation segments.

use atmo_core::RobotConfig;

use crate::Result;
use crate::data::Prepared;
use crate::recording::Recording;
use crate::selection;

/// The recording prepared for fitting, with its segments.
#[derive(Debug, Clone)]
pub struct Residuals {
    pub prep: Prepared,
    /// 1 / noise floor of each channel.
    pub channel_weights: [f64; 6],
    /// Cross-validation segment of each fit row.
    pub seg_of: Vec<Option<usize>>,
    pub nseg: usize,
    /// Indices of the rows used for fitting.
    pub fit_rows: Vec<usize>,
}

impl Residuals {
    /// Residuals of the nominal model of `robot` along `rec`.
    pub fn new(rec: &Recording, robot: &RobotConfig) -> Result<Self> {
        let prep = Prepared::new(rec, robot)?;
        let channel_weights = prep.floor.map(|f| 1.0 / f);
        let (seg_of, nseg) = selection::segments(&prep);
        let fit_rows = prep.fit_rows().collect();
        Ok(Self {
            prep,
            channel_weights,
            seg_of,
            nseg,
            fit_rows,
        })
    }

    /// Weight of each residual entry (`6 k + channel`): 1 / the channel's
    /// noise floor.
    pub fn floor_weights(&self) -> Vec<f64> {
        (0..6 * self.prep.n)
            .map(|i| self.channel_weights[i % 6])
            .collect()
    }

    /// Every segment active.
    pub fn all_segments(&self) -> Vec<bool> {
        vec![true; self.nseg]
    }

    /// Time from the first to the last row (s).
    pub fn duration(&self) -> f64 {
        self.prep.t[self.prep.n - 1] - self.prep.t[0]
    }
}
