//! The three benchmark situations, shared by `benches/rti.rs` and
//! `examples/tick_timing.rs`. Each records a short closed loop against the
//! atmo-core model so that the timed ticks see realistic estimates and plans.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use atmo_core::RobotConfig;
use atmo_core::control::blending_alpha;
use atmo_core::model::{Model, State, idx};
use atmo_mpc::{Formulation, Mpc, MpcSettings};

pub const NAMES: [&str; 3] = ["hover", "morphing_50deg", "transition_65deg"];

/// Horizon parameters of one situation.
#[derive(Debug, Clone, Copy)]
pub struct Scenario {
    pub reference: State,
    pub start: State,
    pub varphi: f64,
    pub tilt_rate: f64,
    pub tilt_max: f64,
    pub alpha: f64,
}

fn at_height(height: f64) -> State {
    let mut x = State::zeros();
    x[idx::Z] = -height;
    x
}

pub fn scenario(name: &str) -> Scenario {
    let cfg = RobotConfig::atmo();
    let z_star = cfg.limits.transition_height;
    let mut start = at_height(1.0);
    start[idx::X] = 0.3;
    start[idx::ROLL] = 0.15;
    start[idx::VY] = 0.5;
    match name {
        "hover" => Scenario {
            reference: at_height(1.0),
            start,
            varphi: 0.0,
            tilt_rate: 0.0,
            tilt_max: 0.0,
            alpha: 1.0,
        },
        // Morphing in flight: 45 deg and tilting at full speed towards the
        // 50 deg in-flight limit, so the horizon's tilt changes stage by stage.
        "morphing_50deg" => {
            let varphi = 45f64.to_radians();
            Scenario {
                reference: at_height(1.0),
                start,
                varphi,
                tilt_rate: cfg.limits.tilt_rate_max,
                tilt_max: cfg.limits.tilt_flight_max(),
                alpha: blending_alpha(1.0, varphi, z_star),
            }
        }
        // Past the critical angle near the ground: alpha about 0.2.
        "transition_65deg" => {
            let varphi = 65f64.to_radians();
            let height = 0.2;
            Scenario {
                reference: at_height(0.0),
                start: at_height(height),
                varphi,
                tilt_rate: 0.0,
                tilt_max: varphi,
                alpha: blending_alpha(height, varphi, z_star),
            }
        }
        other => panic!("unknown scenario {other}"),
    }
}

pub fn settings(formulation: Formulation) -> MpcSettings {
    let mut s = MpcSettings::atmo("default").expect("shipped settings");
    s.solver.formulation = formulation;
    s
}

impl Scenario {
    /// Sets the horizon parameters for the tick.
    pub fn apply(&self, mpc: &mut Mpc) {
        mpc.set_reference_constant(&self.reference).unwrap();
        mpc.set_alpha(self.alpha).unwrap();
        mpc.set_tilt_ramp(self.varphi, self.tilt_rate, 0.0, self.tilt_max)
            .unwrap();
    }

    /// A controller warmed up on this situation, and the estimates of a
    /// closed loop of `ticks` ticks (plant: atmo-core RK4, 7 substeps per tick).
    pub fn warmed_up(&self, formulation: Formulation, ticks: usize) -> (Mpc, Vec<State>) {
        self.warmed_up_with(settings(formulation), ticks)
    }

    /// [`Self::warmed_up`] with the given settings.
    pub fn warmed_up_with(&self, settings: MpcSettings, ticks: usize) -> (Mpc, Vec<State>) {
        let mpc = Mpc::new(Model::new(&RobotConfig::atmo()), settings).unwrap();
        self.warmed_up_from(mpc, ticks)
    }

    /// [`Self::warmed_up`] from a controller as given (e.g. with a ground effect).
    pub fn warmed_up_from(&self, mut mpc: Mpc, ticks: usize) -> (Mpc, Vec<State>) {
        self.apply(&mut mpc);
        mpc.reset(&self.start).unwrap();
        let h = mpc.settings().horizon.tick_period / 7.0;
        let body = mpc.model().at_tilt(self.varphi);
        let mut x = self.start;
        let mut estimates = Vec::with_capacity(ticks);
        for _ in 0..ticks {
            estimates.push(x);
            self.apply(&mut mpc);
            let out = mpc.tick(&x).unwrap();
            for _ in 0..7 {
                x = body.rk4_step(&x, &out.u, h);
            }
        }
        (mpc, estimates)
    }
}
