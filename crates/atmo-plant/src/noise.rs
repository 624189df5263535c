//! Seeded random processes. There is no global random state: every noisy
//! component owns its own ChaCha8 stream, derived from the scenario seed and
//! a fixed stream number, so switching one effect on or off does not change
//! the noise another effect draws, and the same seed gives the same run.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Stream numbers of the noisy components.
pub mod stream {
    pub const GROUND_EFFECT: u64 = 1;
    pub const WIND: u64 = 2;
    pub const SENSORS: u64 = 3;
    pub const AUTOPILOT_ESTIMATE: u64 = 4;
    /// The ESCs' speed reports (drawn by atmo-sim's I/O, not the step).
    pub const ROTOR_SPEEDS: u64 = 5;
}

/// The random stream `id` of `seed`.
#[inline(never)] // start-up
pub fn rng(seed: u64, id: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(id);
    rng
}

/// One standard normal draw.
#[inline(always)]
pub fn normal(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// A unit-variance first-order Gauss-Markov (Ornstein-Uhlenbeck) process
/// sampled every `dt`: `n_{k+1} = a n_k + sqrt(1 - a^2) w_k`, `a = exp(-dt / tau)`,
/// `w_k ~ N(0, 1)`. This is the exact discretization, so its variance is 1
/// and its autocorrelation `exp(-|lag| / tau)` whatever the step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussMarkov {
    a: f64,
    b: f64,
    pub value: f64,
}

impl GaussMarkov {
    /// Starts from a stationary draw.
    #[inline(never)] // start-up
    pub fn new(tau: f64, dt: f64, rng: &mut ChaCha8Rng) -> Self {
        let a = (-dt / tau).exp();
        Self {
            a,
            b: (1.0 - a * a).max(0.0).sqrt(),
            value: normal(rng),
        }
    }

    /// Advances one step and returns the new value.
    #[inline(always)]
    pub fn advance(&mut self, rng: &mut ChaCha8Rng) -> f64 {
        self.value = self.a * self.value + self.b * normal(rng);
        self.value
    }
}
