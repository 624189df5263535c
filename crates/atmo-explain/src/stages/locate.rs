//! Stage 2, locate: where the nominal model's residual is beyond the noise
//! floor (see [`crate::regions`]), and its RMS there.

use crate::data::Prepared;
use crate::explanation::RmsTable;
use crate::regions::{self, Location};
use crate::stages::Residuals;

/// Where the nominal model disagrees with the recording.
#[derive(Debug, Clone)]
pub struct Mismatch {
    pub location: Location,
    /// Per row: inside the located region.
    pub region: Vec<bool>,
    /// Held-out RMS of the nominal model (it fits nothing, so all of it is
    /// held out).
    pub rms: RmsTable,
}

/// Locates the nominal model's residual.
pub fn locate_mismatch(res: &Residuals) -> Mismatch {
    let prep = &res.prep;
    let location = regions::locate(prep, &prep.resid, &res.fit_rows);
    let region = location.region_mask(prep);
    let rms = rms_table(
        prep,
        &prep.resid,
        &res.fit_rows,
        &region,
        &location.channels,
    );
    Mismatch {
        location,
        region,
        rms,
    }
}

/// RMS of `resid` per channel over `rows` and inside `region`, and over
/// `channels` inside `region` in noise floors.
pub fn rms_table(
    prep: &Prepared,
    resid: &[f64],
    rows: &[usize],
    region: &[bool],
    channels: &[usize],
) -> RmsTable {
    let mut sq = [0.0; 6];
    let mut sq_in = [0.0; 6];
    let mut n_in = 0usize;
    let mut norm = 0.0;
    for &k in rows {
        for c in 0..6 {
            let r = resid[6 * k + c];
            sq[c] += r * r;
            if region[k] {
                sq_in[c] += r * r;
            }
        }
        if region[k] {
            n_in += 1;
            for &c in channels {
                let r = resid[6 * k + c] / prep.floor[c];
                norm += r * r;
            }
        }
    }
    let n = rows.len().max(1) as f64;
    let ni = n_in.max(1) as f64;
    RmsTable {
        per_channel: sq.map(|s| (s / n).sqrt()),
        located_per_channel: sq_in.map(|s| (s / ni).sqrt()),
        located_normalized: (norm / (ni * channels.len().max(1) as f64)).sqrt(),
        located_rows: n_in,
    }
}
