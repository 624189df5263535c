//! Flight review (feature `review`): the landing summary (`summary.json`)
//! and the paper's Fig. 5A, one code for the simulator (`atmo-sim fly`,
//! as it flies) and for any flight log (`atmo-mcap summary`, afterwards).
//!
//! - [`landing`]: [`landing::LandingTracker`] and [`landing::Summary`].
//! - [`figure`]: Fig. 5A and the what-if overlay of a replay (plotters).
//! - [`log`]: both, from a log alone.

pub mod figure;
pub mod landing;
pub mod log;
pub mod success_map;
