//! atmo-mpc: the real-time-iteration nonlinear MPC that flies ATMO.
//!
//! Not built yet (issue 4). It will hold: one Gauss-Newton SQP iteration per
//! tick, split into a preparation phase (shift, linearize along the previous
//! plan with atmo-core's RK4 sensitivities, build the QP) and a feedback phase
//! (insert the estimate, solve with Clarabel updated in place, return u[0]).
