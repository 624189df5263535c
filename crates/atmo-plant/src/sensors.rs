//! What the controller sees: a motion-capture state estimate (rate, latency,
//! noise), the autopilot's own estimate, and a ground-contact signal.
//!
//! The plant keeps the true state of the last `latency / dt` steps in a ring
//! buffer allocated once. At each sample instant `k / rate` it publishes the
//! true state from `latency` earlier plus white Gaussian noise (position,
//! Euler angles, velocity, body rates, each with its own standard
//! deviation). The autopilot's estimate is that sample with a Gauss-Markov
//! error on its vertical velocity, advanced once per sample and drawn from
//! its own random stream (the motion capture's noise is the same with it
//! or without it). With sensors off both estimates are the true state at
//! every step.

use atmo_core::model::{NX, State, idx};
use rand_chacha::ChaCha8Rng;

use crate::config::SensorsConfig;
use crate::noise::{GaussMarkov, normal, rng, stream};

/// One state estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// s, when the estimate became available.
    pub time: f64,
    /// s, the instant it describes (`time - latency`).
    pub measured_at: f64,
    pub state: State,
    /// Counts up by one per published sample.
    pub sequence: u64,
}

/// The motion-capture model.
#[derive(Debug, Clone)]
pub(crate) struct Mocap {
    config: Option<SensorsConfig>,
    dt: f64,
    delay_steps: usize,
    ring: Vec<State>,
    head: usize,
    filled: usize,
    next_sample: u64,
    rng: ChaCha8Rng,
    /// The autopilot's vertical-velocity error (unit variance), if any.
    autopilot_error: Option<(GaussMarkov, ChaCha8Rng)>,
    pub latest: Option<Estimate>,
    /// The autopilot's estimate of the same instant.
    pub autopilot: Option<Estimate>,
}

impl Mocap {
    #[inline(never)] // start-up
    pub fn new(config: Option<SensorsConfig>, dt: f64, seed: u64) -> Self {
        let delay_steps = config
            .as_ref()
            .map_or(0, |c| (c.latency / dt).round() as usize);
        let autopilot_error = config
            .as_ref()
            .filter(|c| c.autopilot_vz_error_std > 0.0)
            .map(|c| {
                let mut rng = rng(seed, stream::AUTOPILOT_ESTIMATE);
                let process =
                    GaussMarkov::new(c.autopilot_vz_error_time, 1.0 / c.rate_hz, &mut rng);
                (process, rng)
            });
        Self {
            config,
            dt,
            delay_steps,
            ring: vec![State::zeros(); delay_steps + 1],
            head: 0,
            filled: 0,
            next_sample: 0,
            rng: rng(seed, stream::SENSORS),
            autopilot_error,
            latest: None,
            autopilot: None,
        }
    }

    /// Records the true state after step number `step` (time `step * dt`)
    /// and publishes a sample if one is due.
    #[inline(always)]
    pub fn record(&mut self, step: u64, x: &State) {
        let time = step as f64 * self.dt;
        let Some(cfg) = &self.config else {
            self.latest = Some(Estimate {
                time,
                measured_at: time,
                state: *x,
                sequence: step,
            });
            self.autopilot = self.latest;
            return;
        };
        self.head = (self.head + 1) % self.ring.len();
        self.ring[self.head] = *x;
        self.filled = (self.filled + 1).min(self.ring.len());
        let period = 1.0 / cfg.rate_hz;
        // Sample k is due at k / rate; publish at the first step at or after it.
        if time + 1e-9 * self.dt < self.next_sample as f64 * period {
            return;
        }
        let delay = self.delay_steps.min(self.filled - 1);
        let index = (self.head + self.ring.len() - delay) % self.ring.len();
        let mut state = self.ring[index];
        let std = [
            cfg.position_std,
            cfg.attitude_std,
            cfg.velocity_std,
            cfg.rate_std,
        ];
        for i in 0..NX {
            state[i] += std[i / 3] * normal(&mut self.rng);
        }
        let sample = Estimate {
            time,
            measured_at: time - delay as f64 * self.dt,
            state,
            sequence: self.next_sample,
        };
        let mut autopilot = sample;
        if let Some((process, rng)) = &mut self.autopilot_error {
            autopilot.state[idx::VZ] += cfg.autopilot_vz_error_std * process.advance(rng);
        }
        self.latest = Some(sample);
        self.autopilot = Some(autopilot);
        self.next_sample += 1;
    }

    /// Ground contact signal for a total wheel normal force (N).
    #[inline(always)]
    pub fn contact_signal(&self, wheel_force: f64) -> bool {
        wheel_force > self.config.as_ref().map_or(0.0, |c| c.contact_threshold)
    }
}
