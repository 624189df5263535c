//! The backup controller: a level descent for when the MPC has failed past
//! its grace (`Mode::Failsafe` with `SolverStatus::Failed`) or the pilot
//! has switched it off, while the estimate is still good, and for a stale
//! estimate while the autopilot's own is fresh (flown on its attitude,
//! rates and vertical speed, the horizontal velocity zeroed: not braked
//! against). Without either, the failsafe's open-loop trim. And for a
//! rotor its ESC reports stopped, on the three rotors left.
//!
//! Without it the failed MPC's last plan was flown on (its first command,
//! held): a robot whose solves never came back hovered or climbed away on
//! a stale collective with nothing holding its attitude (atmo-sim's
//! `the_mpc_failed_for_good_the_backup_lands_level_on_the_wheels` fails
//! with the backup off). This is the cascade every
//! autopilot keeps under its main controller: the roll and pitch held level
//! and every body rate damped by a critically damped PD at
//! `failsafe.backup_attitude_bandwidth` (the heading is let go: the yaw
//! rate is damped, not the angle), the horizontal velocity damped by
//! leaning against it (at most [`MAX_LEAN`]), and the vertical speed held at
//! `failsafe.backup_descent_speed` down by a PI loop
//! [`VERTICAL_SEPARATION`] times slower than the attitude's, the thrust
//! divided by the tilt of the body so that leaning costs no height. The
//! wrench is allocated to the four rotors through the model at the tilt
//! flown, with the observer's learned wrench (`TiltedBody::commands_for`;
//! with a rotor stopped `TiltedBody::commands_without`: the lift and what
//! the three can give of the torque), the lift cut where a rotor would
//! pass full thrust (`level_before_lift`), and each command clamped to
//! [0, 1]. With a rotor stopped the angle term is the spin's steering
//! instead ([`spin_steering`]) and no lift is cut for the torque: three
//! rotors cannot level the body, they can turn its spin to the vertical
//! (docs/decisions/2026-12-07-spin-steering.md); the lift the diagonal
//! pair cannot give the stopped rotor's partner gives, as far as its torque
//! is asked for (`partner_lifts`). The arms meanwhile go to the
//! failsafe descent's landing tilt (`monitor.rotor_out_landing_tilt_deg`),
//! so that it comes down on its wheels, not its base.
//!
//! Limits: a weak or stuck rotor learned by `rotor_estimate` is not flown
//! around (only a stopped one), a stopped rotor's descent in flight lands
//! hard (about 1 m/s) and crashes on about one flight in seven
//! (docs/faults.md), it
//! knows no ground effect (the vertical loop's integral takes it up) and
//! it damps the velocity, it does not hold a position: it lands where its
//! velocity at the failure carries it to.
//!
//! Pure, fixed-size, no allocation: it runs on the control path.

use atmo_core::model::{Input, State, TiltedBody, idx, level_cosine};
use nalgebra::{Matrix3, Vector3};

/// How much slower the vertical speed loop is than the attitude loop: a
/// cascade's outer loop a factor of several below the inner one does not
/// fight it (the usual rule of thumb; 5).
pub const VERTICAL_SEPARATION: f64 = 5.0;

/// The most the backup leans to brake a horizontal velocity, rad (about
/// 10 deg: a tenth of the thrust to the side).
pub const MAX_LEAN: f64 = 0.175;

/// The body's tilt from level below which the thrust is no longer divided
/// by it (cos 60 deg): a robot rolled past that gets the level thrust, not
/// twice it.
const MIN_TILT_COSINE: f64 = 0.5;

/// A rotor its ESC reports stopped, and the thrust it still delivers (a
/// fraction of full: its measured speed squared).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StoppedRotor {
    /// 0-based.
    pub rotor: usize,
    pub delivered: f64,
}

/// The level descent's memory: the vertical loop's integral.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LevelDescent {
    /// The integral of the vertical speed error, m/s^2 of acceleration.
    integral: f64,
}

impl LevelDescent {
    /// Forgets the integral (a new failsafe).
    pub fn reset(&mut self) {
        self.integral = 0.0;
    }

    /// The rotor commands of the level descent at `state` for `body` (the
    /// model at the tilt flown, with the wrench the observer learned),
    /// `dt` after the last call: attitude bandwidth `bandwidth` (rad/s),
    /// descent speed `descent_speed` (m/s, down). The vertical loop is a
    /// critically damped PI: the model has no ground effect, whose lift
    /// near the ground a proportional loop alone would hover on. `None`
    /// when the model has no allocation there (the caller falls back).
    ///
    /// With a rotor `stopped` (its ESC says so) the three rotors left fly
    /// it (`TiltedBody::commands_without`): the heading let go, the body
    /// spinning up on the pair's unopposed drag torque, its spin steered
    /// to the vertical ([`spin_steering`]) and its rates damped, of that
    /// torque the part the three can give, the lift never cut for it (what
    /// that leaves undone: docs/faults.md, the stopped rotor in flight).
    #[allow(clippy::too_many_arguments)] // the descent's inputs, each a number
    pub fn command(
        &mut self,
        body: &TiltedBody,
        state: &State,
        dt: f64,
        bandwidth: f64,
        descent_speed: f64,
        stopped: Option<StoppedRotor>,
    ) -> Option<Input> {
        // The horizontal velocity damped by leaning against it (FRD body,
        // NED world: nose up brakes forward, right wing down pushes right),
        // at the vertical loop's gain, the lean bounded.
        let gain = bandwidth / VERTICAL_SEPARATION;
        let (sin_yaw, cos_yaw) = state[idx::YAW].sin_cos();
        let forward = cos_yaw * state[idx::VX] + sin_yaw * state[idx::VY];
        let right = -sin_yaw * state[idx::VX] + cos_yaw * state[idx::VY];
        let lean = |a: f64| (a / body.gravity).clamp(-MAX_LEAN, MAX_LEAN);
        let pitch_wanted = lean(gain * forward);
        let roll_wanted = lean(-gain * right);
        let angle_error = Vector3::new(
            state[idx::ROLL] - roll_wanted,
            state[idx::PITCH] - pitch_wanted,
            0.0,
        );
        let rates = Vector3::new(state[idx::WX], state[idx::WY], state[idx::WZ]);
        // Critically damped on four rotors; on three the angle term is the
        // spin's steering (they cannot level the body, they can steer its
        // spin), the rates damped alike (the nutation that would keep the
        // body coned round its spin).
        let damping = -rates * (2.0 * bandwidth);
        let torque = match stopped {
            Some(_) => spin_steering(&body.inertia, state, bandwidth) + body.inertia * damping,
            None => body.inertia * (damping - angle_error * (bandwidth * bandwidth)),
        };
        // NED: z down, the velocity in the world frame.
        let error = descent_speed - state[idx::VZ];
        // Critically damped: s^2 + k s + k^2 / 4. The integral is bounded
        // by half of gravity (no wind-up on the ground).
        let limit = 0.5 * body.gravity;
        self.integral = (self.integral + 0.25 * gain * gain * error * dt).clamp(-limit, limit);
        let acceleration_down = gain * error + self.integral;
        let tilt_cosine = level_cosine(state).max(MIN_TILT_COSINE);
        let force_z = body.mass * (acceleration_down - body.gravity) / tilt_cosine;
        let allocate = |force_z: f64| match stopped {
            Some(s) => body.commands_without(s.rotor, s.delivered, force_z, &torque),
            None => body.commands_for(force_z, &torque),
        };
        // Levelling is the spin's on three rotors: no lift is cut for it;
        // the lift the pair cannot give, the partner gives where its torque
        // is asked for.
        let u = match stopped {
            Some(s) => partner_lifts(body, s.rotor, &torque, allocate(force_z)),
            None => level_before_lift(allocate, force_z),
        };
        u.iter()
            .all(|v| v.is_finite())
            .then(|| u.map(|v| v.clamp(0.0, 1.0)))
    }
}

/// The torque (body frame) that turns the body's angular momentum towards
/// the world's vertical at `state`: with one rotor stopped, what levels the
/// robot on average. Three rotors torque the body about one axis and a
/// half (the pair's differential and the partner's push), not about the
/// pair's own diagonal, and their unopposed drag spins the body up. A
/// spinning body answers a torque by moving its angular momentum `H`
/// along it (dH/dt = torque: gyroscopic precession, not a tip), and a
/// body that spins about the vertical cones its thrust round it, which is
/// vertical on average (Mueller and D'Andrea's relaxed hover): so the
/// torque asked is `bandwidth |H|` times the part of the vertical (signed
/// as `H`) across `H`, which turns `H` to the vertical at `bandwidth`
/// rad/s per rad, whatever the spin. Without a spin it asks next to
/// nothing: a body that does not spin cannot be levelled about the pair's
/// diagonal by anything left. The allocation takes what the three rotors
/// can give of it (`TiltedBody::commands_without`), which the spin turns
/// round the world.
pub fn spin_steering(inertia: &Matrix3<f64>, state: &State, bandwidth: f64) -> Vector3<f64> {
    let down = world_down(state);
    let momentum = inertia * Vector3::new(state[idx::WX], state[idx::WY], state[idx::WZ]);
    let size = momentum.norm();
    if size <= f64::EPSILON {
        return Vector3::zeros();
    }
    let axis = momentum / size;
    let vertical = down * momentum.dot(&down).signum();
    (vertical - axis * vertical.dot(&axis)) * (bandwidth * size)
}

/// With rotor `stopped` out, the commands `u` of the three left with the
/// lift the diagonal pair cannot give (its commands past full) taken from
/// the stopped rotor's diagonal partner, as far as the partner's torque is
/// asked for: at most the command whose torque is the part of `torque`
/// (the steering's and the damping's) along the partner's lever. Why:
/// the allocation leaves the partner off whenever the exact torque would
/// need it pulling, and the pair at full cannot hold the weight with the
/// arms at the landing tilt. The partner pushes about one axis only,
/// fixed in the body and turning round the world with the spin; pushing
/// for lift where the steering asks that torque lifts without tipping,
/// pushing past it tips the body
/// (docs/decisions/2026-12-07-partner-lift.md).
fn partner_lifts(body: &TiltedBody, stopped: usize, torque: &Vector3<f64>, mut u: Input) -> Input {
    let (partner, a, b) = body.diagonals(stopped);
    // NED: a lift is a negative body z force.
    let missing: f64 = [a, b]
        .iter()
        .map(|&r| (u[r] - 1.0).max(0.0) * body.thrust_force[(2, r)])
        .sum();
    let per_command = body.thrust_force[(2, partner)];
    let lever = body.roll_pitch_lever(partner);
    let asked = lever.dot(&torque.xy()) / lever.norm_squared();
    if missing >= 0.0 || per_command >= 0.0 || asked.is_nan() || asked <= 0.0 {
        return u;
    }
    let lifting = u[partner].max(0.0) + missing / per_command;
    u[partner] = u[partner].max(lifting.min(asked));
    u
}

/// The world's down (NED z) in the body frame at `state`'s roll and pitch.
fn world_down(state: &State) -> Vector3<f64> {
    let (sin_roll, cos_roll) = state[idx::ROLL].sin_cos();
    let (sin_pitch, cos_pitch) = state[idx::PITCH].sin_cos();
    Vector3::new(-sin_pitch, sin_roll * cos_pitch, cos_roll * cos_pitch)
}

/// Bisection steps of [`level_before_lift`]: the lift found to 2^-12 of
/// what was asked.
const DESATURATION_STEPS: usize = 12;

/// The allocation `allocate` of the lift `force_z` (negative: up) and the
/// torque it was built with, the lift cut where a rotor would have to
/// give more than full thrust: a rotor clamped at full takes the torque
/// away with it, and a robot that cannot hold level falls on its side
/// however much lift it has (the usual mixer's desaturation). The lift
/// kept is the largest fraction of `force_z` with no command past 1,
/// found by bisection (the allocation is piecewise linear in the lift).
fn level_before_lift(allocate: impl Fn(f64) -> Input, force_z: f64) -> Input {
    let u = allocate(force_z);
    if !u.iter().all(|v| v.is_finite()) || u.max() <= 1.0 {
        return u;
    }
    let (mut fits, mut over) = (0.0, 1.0);
    for _ in 0..DESATURATION_STEPS {
        let k = 0.5 * (fits + over);
        if allocate(k * force_z).max() <= 1.0 {
            fits = k;
        } else {
            over = k;
        }
    }
    allocate(fits * force_z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use atmo_core::{Model, RobotConfig};

    fn body() -> TiltedBody {
        Model::new(&RobotConfig::atmo()).at_tilt(0.0)
    }

    #[test]
    fn level_and_at_the_descent_speed_it_commands_the_hover_trim() {
        let b = body();
        let mut x = State::zeros();
        x[idx::VZ] = 0.3;
        let u = LevelDescent::default()
            .command(&b, &x, 0.01, 10.0, 0.3, None)
            .unwrap();
        assert!((u - b.hover_trim()).norm() < 1e-12, "{u}");
    }

    #[test]
    fn it_rights_a_rolled_robot_and_brakes_a_fall() {
        let b = body();
        let mut x = State::zeros();
        x[idx::ROLL] = 0.2;
        x[idx::VZ] = 0.3;
        let u = LevelDescent::default()
            .command(&b, &x, 0.01, 10.0, 0.3, None)
            .unwrap();
        let torque = b.thrust_torque * u + b.first_moment.cross(&Vector3::new(0.0, 0.0, b.gravity));
        assert!(torque.x < -0.1, "rolled right, it rolls left: {torque}");
        x[idx::ROLL] = 0.0;
        x[idx::VZ] = 2.0;
        let fast = LevelDescent::default()
            .command(&b, &x, 0.01, 10.0, 0.3, None)
            .unwrap();
        assert!(fast.sum() > b.hover_trim().sum() + 0.1, "{fast}");
        x[idx::VZ] = -2.0;
        let climbing = LevelDescent::default()
            .command(&b, &x, 0.01, 10.0, 0.3, None)
            .unwrap();
        assert!(climbing.sum() < b.hover_trim().sum() - 0.1, "{climbing}");
        assert!(climbing.iter().all(|v| (0.0..=1.0).contains(v)));
    }

    #[test]
    fn it_leans_against_a_horizontal_velocity_whatever_the_heading() {
        let b = body();
        let gravity_torque = b.first_moment.cross(&Vector3::new(0.0, 0.0, b.gravity));
        let torque = |x: &State| {
            let u = LevelDescent::default()
                .command(&b, x, 0.01, 10.0, 0.3, None)
                .unwrap();
            b.thrust_torque * u + gravity_torque
        };
        let mut x = State::zeros();
        x[idx::VZ] = 0.3;
        // Flying forward (north, heading north): nose up.
        x[idx::VX] = 1.0;
        assert!(torque(&x).y > 0.1, "{}", torque(&x));
        // Flying east, heading east: forward again, nose up.
        x[idx::VX] = 0.0;
        x[idx::VY] = 1.0;
        x[idx::YAW] = std::f64::consts::FRAC_PI_2;
        assert!(torque(&x).y > 0.1, "{}", torque(&x));
        // Flying east, heading north: to the right, left wing down.
        x[idx::YAW] = 0.0;
        assert!(torque(&x).x < -0.1, "{}", torque(&x));
        // Leaned as far as it leans, it holds there.
        x[idx::VY] = 100.0;
        x[idx::ROLL] = -MAX_LEAN;
        assert!(torque(&x).norm() < 1e-9, "{}", torque(&x));
    }

    #[test]
    fn held_above_its_descent_speed_the_integral_takes_thrust_off_until_bounded() {
        // Hovering (a lift the model lacks holds it up): the integral asks
        // for less thrust each tick, down to half of gravity.
        let b = body();
        let x = State::zeros();
        let mut descent = LevelDescent::default();
        let first = descent
            .command(&b, &x, 0.01, 10.0, 0.3, None)
            .unwrap()
            .sum();
        let mut last = first;
        for _ in 0..2000 {
            last = descent
                .command(&b, &x, 0.01, 10.0, 0.3, None)
                .unwrap()
                .sum();
        }
        assert!(last < first - 0.1, "{first} -> {last}");
        assert!((descent.integral - 0.5 * b.gravity).abs() < 1e-9);
        descent.reset();
        assert_eq!(descent, LevelDescent::default());
    }
    #[test]
    fn asked_more_lift_than_the_rotors_have_it_keeps_the_torque_and_cuts_the_lift() {
        // Rolled and falling fast: the lift wanted is past full thrust.
        // Clamping each rotor at full would leave no roll torque; the cut
        // lift leaves the asked torque exactly.
        let b = body();
        let mut x = State::zeros();
        x[idx::ROLL] = 0.2;
        x[idx::VZ] = 5.0;
        let u = LevelDescent::default()
            .command(&b, &x, 0.01, 10.0, 0.3, None)
            .unwrap();
        let gravity_torque = b.first_moment.cross(&Vector3::new(0.0, 0.0, b.gravity));
        let torque = b.thrust_torque * u + gravity_torque;
        let asked = b.inertia * Vector3::new(-100.0 * 0.2, 0.0, 0.0);
        assert!((torque - asked).norm() < 1e-3, "{torque} {asked}");
        assert!((u.max() - 1.0).abs() < 1e-3, "{u}");
        assert!(u.sum() > b.hover_trim().sum(), "{u}");
    }

    #[test]
    fn spinning_tipped_it_turns_the_spin_to_the_vertical_and_level_it_asks_nothing() {
        let b = body();
        for (roll, pitch, spin) in [(0.3, 0.0, -12.0), (-0.2, 0.25, 15.0), (0.1, -0.4, -4.0)] {
            let mut x = State::zeros();
            x[idx::ROLL] = roll;
            x[idx::PITCH] = pitch;
            x[idx::WZ] = spin;
            let torque = spin_steering(&b.inertia, &x, 10.0);
            // dH = torque dt: the angle between H and the vertical (signed
            // as H) shrinks.
            let h = b.inertia * Vector3::new(0.0, 0.0, spin);
            let vertical = world_down(&x) * h.dot(&world_down(&x)).signum();
            let angle = |h: &Vector3<f64>| h.angle(&vertical);
            let after = h + torque * 1e-3;
            assert!(angle(&after) < angle(&h), "{roll} {pitch} {spin}: {torque}");
            // The turn is at the bandwidth: 10 rad/s per rad, near enough
            // for a small step (the torque is across H).
            let rate = (angle(&h) - angle(&after)) / 1e-3;
            assert!(
                (rate / (10.0 * angle(&h).sin()) - 1.0).abs() < 0.01,
                "{rate}"
            );
        }
        // Spinning about the vertical, or not turning at all: nothing.
        let mut x = State::zeros();
        x[idx::WZ] = 12.0;
        let level = spin_steering(&b.inertia, &x, 10.0);
        // The inertia's products tilt H off body z by a few thousandths.
        assert!(
            level.norm() < 0.05 * b.inertia[(2, 2)] * 12.0 * 10.0,
            "{level}"
        );
        x[idx::WZ] = 0.0;
        x[idx::ROLL] = 0.3;
        assert_eq!(spin_steering(&b.inertia, &x, 10.0), Vector3::zeros());
    }

    #[test]
    fn the_lift_the_pair_cannot_give_the_partner_gives_where_its_torque_is_asked() {
        let b = Model::new(&RobotConfig::atmo()).at_tilt(40f64.to_radians());
        let stopped = 1;
        let (partner, a, c) = b.diagonals(stopped);
        let lever = b.roll_pitch_lever(partner);
        let along = Vector3::new(lever.x, lever.y, 0.0) / lever.norm();
        let mut u = Input::zeros();
        u[a] = 1.3;
        u[c] = 1.2;
        let lift = |u: &Input| {
            (0..4)
                .map(|r| u[r].min(1.0) * b.thrust_force[(2, r)])
                .sum::<f64>()
        };
        // Its torque asked, plenty of it: the lift past full comes back.
        let out = partner_lifts(&b, stopped, &(along * 10.0), u);
        assert!(out[partner] > 0.0, "{out}");
        let unclamped = u[a] * b.thrust_force[(2, a)] + u[c] * b.thrust_force[(2, c)];
        assert!((lift(&out) - unclamped).abs() < 1e-9, "{out}");
        // A little of it asked: that much torque and no more.
        let out = partner_lifts(&b, stopped, &(along * 0.2), u);
        assert!((lever.norm() * out[partner] - 0.2).abs() < 1e-9, "{out}");
        // NED: more lift is a more negative force, short of the whole.
        assert!(
            lift(&out) < lift(&u) && lift(&out) - unclamped > 1e-3,
            "{out}"
        );
        // Its torque unwanted, or the pair not at full: nothing changes.
        assert_eq!(partner_lifts(&b, stopped, &(-along), u), u);
        let mut under = u;
        under[a] = 0.9;
        under[c] = 0.8;
        assert_eq!(partner_lifts(&b, stopped, &along, under), under);
        assert_eq!(out[stopped], 0.0);
    }
}
