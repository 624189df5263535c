//! atmo-mpc: the real-time-iteration (RTI) nonlinear MPC that flies ATMO.
//!
//! # The problem
//!
//! With the tilt sequence `varphi_k` (a known parameter: the current angle
//! plus the commanded tilt velocity times `t_k`, clamped), stage length
//! `dt = T / N` and `F_k(x, u) = RK4(f(., ., varphi_k), x, u, dt)`:
//!
//! ```text
//! min   sum_{k<N} [ |x_k - r_k|^2_{Q(alpha)} + |u_k - u_ref,k|^2_{R(alpha)} ] + |x_N - r_N|^2_{Q_N}
//! s.t.  x_0 = x_est,  x_{k+1} = F_k(x_k, u_k),  0 <= u_k <= 1
//! Q(alpha) = alpha Q1 + (1 - alpha) Q2,  R(alpha) = alpha R1 + (1 - alpha) R2,
//! Q_N = terminal_scale * Q(alpha),  u_ref,k = clamp(hover_trim(varphi_k), 0, 1)
//! ```
//!
//! With a ground-effect surface ([`Mpc::set_ground_effect`], from `[model]
//! ground_effect` in `config/mpc.toml`), `f` is atmo-core's
//! `GroundedBody`: rotor i's thrust times `1 + g(h_i, varphi_k)`, h_i its hub
//! height above the ground plane [`Mpc::set_ground_height`], linearized
//! exactly (height through position and attitude). `"none"` is the nominal
//! model (measured better with the tilt on the paper's ramp:
//! docs/ground_effect.md); the shipped default is `"default"` with the
//! tilt planned (below; docs/landing.md).
//!
//! # The tilt as a decision (transition)
//!
//! With `[tilt_plan]` configured and a [`TiltPlan`] set ([`Mpc::set_tilt_plan`],
//! the flight stack does it in the transition), the tilt is no parameter:
//! the model is [`tilt_model`]'s 13 states `(x, varphi)` and 5 inputs
//! `(u, omega)`, `varphi_dot = omega`, with `df/dvarphi` exact (atmo-core
//! `TiltPartial`), and the same RTI QP (generic in its size) carries the
//! tilt-rate box `[rate_min, rate_max]` narrowed by the tilt limits at the
//! plan's tilt, the rotor box `[0, thrust_max]`, and the landing objective:
//! the tilt's distance from its limit and the vertical speed weighed at the
//! touchdown predicted along the plan (wheel clearance crossing zero), the
//! state cost faded out past it, the descent held to its reference before
//! it (`controller::tilt_plan`, docs/landing.md). The feedback is the same
//! exact homotopy; [`TickOutput::tilt_rate`] is the planned rate to command.
//!
//! The yaw entry of `x - r` is the wrapped difference (in (-pi, pi]), so a
//! reference at +179 deg and a state at -179 deg are 2 deg apart.
//!
//! # One Gauss-Newton step per tick (RTI)
//!
//! In deviations from the plan (`xbar`, `ubar`): `dx_k = x_k - xbar_k`,
//! `du_k = u_k - ubar_k`, with `(A_k, B_k)` the exact sensitivities of the
//! RK4 step at `(xbar_k, ubar_k)` and `d_k = F_k(xbar_k, ubar_k) - xbar_{k+1}`:
//!
//! ```text
//! min  1/2 sum_k |dx_k + e_k|^2_{Q_k} + 1/2 sum_k |du_k + ubar_k - u_ref,k|^2_R
//! s.t. dx_0 = x_est - xbar_0,  dx_{k+1} = A_k dx_k + B_k du_k + d_k,  -ubar_k <= du_k <= 1 - ubar_k
//! ```
//!
//! (`e_k = xbar_k - r_k`, yaw wrapped). **Preparation** ([`Mpc::prepare`],
//! before the estimate arrives): shift the plan by one controller period
//! (linear interpolation between stages, the last state continued by one RK4
//! step), compute `A_k, B_k, d_k` along it, build the QP and write it into
//! Clarabel. **Feedback** ([`Mpc::feedback`]): insert `dx_0`, solve, apply
//! the step to the plan (`xbar += dx`, `ubar += du`), return `u_0`.
//!
//! # Two formulations of the same QP
//!
//! - *Sparse* (multiple shooting): variables `(dx_0, du_0, ..., dx_N)`,
//!   diagonal P, `12 (N + 1)` equality rows and `8N` bound rows; feedback
//!   changes only the first 12 entries of b.
//! - *Condensed*: states eliminated with
//!   `dx_k = Phi_k dx_0 + sum_{j<k} G_{k,j} du_j + w_k`
//!   (`Phi_{k+1} = A_k Phi_k`, `G_{k+1,k} = B_k`, `G_{k+1,j} = A_k G_{k,j}`,
//!   `w_{k+1} = A_k w_k + d_k`). With `S_N = Q_N`,
//!   `S_k = Q_k + A_k' S_{k+1} A_k`, `lambda_k = Q_k c_k + A_k' lambda_{k+1}`,
//!   `c_k = w_k + e_k`, the QP in the 4N inputs is
//!   `min 1/2 du' H du + (g0 + M dx_0)' du`, `-ubar <= du <= 1 - ubar`, with
//!   `H_ij = B_i' S_{i+1} G_{i+1,j} (+ R on the diagonal)`,
//!   `M_i = B_i' S_{i+1} Phi_{i+1}`, `g0_i = B_i' lambda_{i+1} + R (ubar_i - u_ref,i)`.
//!   The O(N^2) condensing is in the preparation; feedback only forms
//!   `g0 + M dx_0` (a 40 x 12 product) and solves. States are recovered by
//!   the linear recursion.
//!
//! Which one is the default is decided by measurement (`benches/rti.rs`,
//! BENCHMARKS.md); `config/mpc.toml` selects it.
//!
//! # Feedback in microseconds: the exact parametric solution
//!
//! In the condensed QP the estimate enters only the linear term
//! `q(dx_0) = g0 + M dx_0` and the constraints are boxes, so the solution is
//! a piecewise-affine function of `dx_0`, affine on each active set. With
//! `feedback.method = "homotopy"` (the default):
//!
//! - the **preparation** predicts `dx_0` (`feedback.predictor`: one RK4 step
//!   of the model from the last estimate with the applied command, or the
//!   shifted plan, `dx_0 = 0`), has Clarabel solve the QP there, reads the
//!   active set off its solution (a bound is active where its slack is below
//!   its multiplier), factors `H_FF` (free inputs) and corrects that active
//!   set into the exact solution at the prediction ([`homotopy`]);
//! - the **feedback** forms `q` at the actual `dx_0` and walks the
//!   parametric active-set homotopy (qpOASES's online active-set strategy)
//!   along the line from the predicted to the actual `q`, one bound added or
//!   dropped per breakpoint by a rank-one update of the Cholesky factor. The
//!   result is the QP's exact solution (round-off of one Cholesky solve).
//!   More than `feedback.max_active_set_changes` changes, or a near-singular
//!   pivot, fall back to a full Clarabel solve at the estimate, reported as
//!   [`FeedbackPath::Clarabel`] with the reason and counted
//!   ([`Mpc::homotopy_fallbacks`]).
//!
//! The sparse formulation has equality constraints in which `dx_0` appears
//! (`dx_0 = x_est - xbar_0`) and keeps the Clarabel feedback.
//!
//! # Solver
//!
//! Clarabel (interior point) is built once in [`Mpc::new`] with a fixed
//! sparsity pattern (structural zeros kept, presolve off, verbose off); each
//! tick only `update_P/q/A/b` write values. The per-solve time limit is ours
//! ([`qp::TimedSolver`], a termination callback on a monotonic clock):
//! Clarabel 0.11's own limit counts set-up time and a timer that is never
//! reset, and after about 10^4 solves it ended every solve at iteration 0.
//!
//! A solve ends as an [`Outcome`]: `Solved`, `Degraded` (reduced accuracy,
//! or an iteration or time limit hit with an iterate that meets Clarabel's
//! reduced tolerances: it is used, inputs clamped to [0, 1]), `Fallback` (no
//! usable solution, a limit hit earlier, a non-finite estimate, or a failed
//! preparation: the shifted previous plan is flown, up to
//! `failure.grace_ticks` ticks in a row) and then `Failed`. A plan whose
//! linearization is not finite is restarted from the next estimate.
//!
//! Nothing in the tick allocates in this crate (`tests/no_alloc.rs`; Clarabel's
//! `solve` itself allocates one block per call in its timers, now in the
//! preparation; the homotopy feedback allocates nothing).

pub mod controller;
pub mod error;
pub mod homotopy;
pub mod qp;
pub mod settings;
pub mod tilt_model;

pub use controller::{
    AlphaSchedule, DegradedCause, FailureCause, FeedbackPath, HomotopyFallback, Mpc, Outcome,
    SqpReport, TickOutput, TickTimings, TiltPlan, YawCost, wheel_clearance,
    wheel_clearance_at_attitude, wrap_angle,
};
pub use error::{MpcError, Result};
pub use homotopy::{Bound, BoxHomotopy, HomotopyStop};
pub use qp::cuts::{CutWindow, SolverCuts};
pub use qp::{LinearizedHorizon, QpSnapshot, SolveReport};
pub use settings::{
    CostPreset, FeedbackMethod, FeedbackSettings, Formulation, MpcFile, MpcSettings, Predictor,
    SolverSettings,
};
