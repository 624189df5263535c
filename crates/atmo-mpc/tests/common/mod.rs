//! Closed-loop harness shared by the integration tests: the atmo-core model
//! as the plant (RK4 at about 1 ms), the MPC at 150 Hz.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]
#![allow(dead_code)]

use atmo_core::RobotConfig;
use atmo_core::model::{Input, Model, State, idx};
use atmo_mpc::{Formulation, Mpc, MpcSettings, Outcome, SolverSettings, TickOutput};

/// Plant substeps per controller tick: 150 Hz / 7 = 0.95 ms.
pub const SUBSTEPS: usize = 7;

pub fn settings(formulation: Formulation) -> MpcSettings {
    let mut s = MpcSettings::atmo("default").expect("shipped settings");
    s.solver.formulation = formulation;
    // The shipped wall-clock limit (4 ms) makes a solve's outcome depend on
    // how loaded the machine is; these tests check numbers, so they lift it.
    // The limit itself is tested in `time_limit_gives_a_degraded_command`.
    s.solver.time_limit = 1.0;
    s
}

pub fn controller(formulation: Formulation) -> Mpc {
    Mpc::new(Model::new(&RobotConfig::atmo()), settings(formulation)).expect("controller builds")
}

pub fn hover_at(x: f64, y: f64, height: f64) -> State {
    let mut s = State::zeros();
    s[idx::X] = x;
    s[idx::Y] = y;
    s[idx::Z] = -height;
    s
}

/// Closed loop record.
#[derive(Default)]
pub struct Trace {
    pub states: Vec<State>,
    pub inputs: Vec<Input>,
    pub outcomes: Vec<Outcome>,
    pub tilts: Vec<f64>,
}

impl Trace {
    pub fn last(&self) -> &State {
        self.states.last().unwrap()
    }
    pub fn inputs_within_bounds(&self) -> bool {
        self.inputs
            .iter()
            .all(|u| u.iter().all(|v| (0.0..=1.0).contains(v)))
    }
    pub fn fresh_fraction(&self) -> f64 {
        self.outcomes.iter().filter(|o| o.is_fresh()).count() as f64 / self.outcomes.len() as f64
    }
}

/// Runs `ticks` controller ticks from `x0`. `setup(mpc, tick, state)`
/// sets the horizon parameters each tick and returns the plant's tilt.
pub fn run(
    mpc: &mut Mpc,
    x0: State,
    ticks: usize,
    mut setup: impl FnMut(&mut Mpc, usize, &State) -> f64,
) -> Trace {
    let tick_period = mpc.settings().horizon.tick_period;
    let h = tick_period / SUBSTEPS as f64;
    let mut x = x0;
    let mut trace = Trace::default();
    let varphi0 = setup(mpc, 0, &x);
    mpc.reset(&x).unwrap();
    let mut varphi = varphi0;
    for tick in 0..ticks {
        if tick > 0 {
            varphi = setup(mpc, tick, &x);
        }
        let out: TickOutput = mpc.tick(&x).expect("tick");
        let body = mpc.model().at_tilt(varphi);
        for _ in 0..SUBSTEPS {
            x = body.rk4_step(&x, &out.u, h);
        }
        trace.states.push(x);
        trace.inputs.push(out.u);
        trace.outcomes.push(out.outcome);
        trace.tilts.push(varphi);
    }
    trace
}

/// Clarabel as a reference solver: tolerances 1e-11, iterative refinement,
/// no time limit to speak of (the rest as `shipped`).
pub fn reference_settings(shipped: &SolverSettings) -> SolverSettings {
    SolverSettings {
        max_iter: 200,
        time_limit: 10.0,
        tol_gap_abs: 1e-11,
        tol_gap_rel: 1e-11,
        tol_feas: 1e-11,
        iterative_refinement: true,
        max_step_fraction: 0.99,
        ..*shipped
    }
}
