//! Which rotor has failed and how much of its command it still delivers,
//! learned from the disturbance observer once the actuator monitor has
//! seen a rotor fault (docs/faults.md, the actuator table).
//!
//! A rotor that delivers `delta` more thrust (as a command fraction) than
//! the model predicts leaves the wrench `B_i delta` to the observer, where
//! `B_i` is that rotor's column of the thrust wrench at the tilt flown
//! (`TiltedBody::thrust_force` / `thrust_torque`). The four rotors' roll
//! and pitch torques point into four different quadrants, so the sign of
//! the observer's roll and pitch torque names the rotor even when the
//! observer is at its limit on both axes, up to the sign of `delta`: a
//! surplus on a rotor turns the robot as a loss on its diagonal partner
//! does, and the yaw torque tells them apart ([`RotorEstimate::name_rotor`]).
//! A rotor named with a surplus is stuck: out at once, and what it
//! delivers is learned instead of an effectiveness. One that goes out for
//! a loss is believed to give nothing until the observer, on plans that
//! have it out, sees it give something: a rotor stuck below what the
//! plan asked of it looks weak until then.
//!
//! From the detection on, every tick moves the part of the observer's
//! wrench that rotor `i` explains into its effectiveness `e_i`:
//! `delta = <d_rp, B_i,rp> / |B_i,rp|^2`, the rotor commanded `u / e_i`
//! delivered `u (1 + delta / u)` of what was planned, so
//! `e_i <- e_i (1 + delta / u)`, and `B_i delta` leaves the observer. The
//! observer's gain is the adaptation's: `e_i` converges with the torque's
//! time constant (about 0.17 s). The MPC then plans in delivered thrust
//! with rotor `i` bounded by `e_i` (`Mpc::set_rotor_max`) and the command
//! sent is the plan over `e_i`: the optimizer redistributes, the observer
//! is free again for what it learned before.
//!
//! Before a detection nothing here runs: a fault-free flight flies the same
//! commands, bit for bit. Fixed state, no allocation.

use atmo_core::model::{Input, TiltedBody};
use nalgebra::Vector6;

/// A command this small says nothing about the rotor's effectiveness.
const MIN_COMMAND: f64 = 0.05;

/// The failed rotor and its learned effectiveness.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RotorEstimate {
    /// The rotor seen to fail (0-based), once the monitor has detected one.
    rotor: Option<usize>,
    /// What it delivers of its command, in [0, 1].
    effectiveness: f64,
    /// Once out (commanded nothing): the thrust it still delivers, as a
    /// fraction of full (a rotor stuck at a command, not stopped).
    delivered: f64,
    /// It was seen to deliver more than commanded (its effectiveness
    /// learned past `OVER`): stuck, not stopped or weak.
    over: bool,
}

/// An effectiveness learned past this says the rotor gave more than it
/// was commanded: stuck at an earlier command. A weak or stopped rotor
/// never does: at the detection the observer's torque is the lost
/// thrust's, and the learning only lowers the effectiveness from 1.
const OVER: f64 = 1.0;

/// Half the width of the MPC's box around a rotor that delivers what it
/// is not commanded (an interior-point solve wants a box, not a point).
const STUCK_BOX: f64 = 0.01;

impl RotorEstimate {
    /// The rotor (0-based) whose thrust explains the observer's torque `d`
    /// best at `body`, and whether it gives more than commanded (stuck)
    /// rather than less: the largest projection of `-B_i` (a loss) or
    /// `+B_i` (a surplus) on the roll, pitch and yaw torque. A loss on a
    /// rotor and a surplus on its diagonal partner turn the robot alike
    /// in roll and pitch; the yaw tells them apart (diagonal partners
    /// spin the same way and lean the same way about z, so a surplus on
    /// one yaws against a loss on the other).
    pub fn name_rotor(body: &TiltedBody, d: &Vector6<f64>) -> (usize, bool) {
        let mut best = (0, false, f64::NEG_INFINITY);
        for i in 0..4 {
            let b = body.thrust_torque.column(i);
            let along = (b[0] * d[3] + b[1] * d[4] + b[2] * d[5]) / b.norm().max(1e-9);
            for (surplus, score) in [(false, -along), (true, along)] {
                if score > best.2 {
                    best = (i, surplus, score);
                }
            }
        }
        (best.0, best.1)
    }

    /// Starts learning rotor `rotor`: its effectiveness from 1, or, when
    /// `stuck`, what it delivers whatever it is commanded (out at once).
    pub fn start(&mut self, rotor: usize, stuck: bool) {
        if self.rotor.is_none() {
            self.rotor = Some(rotor.min(3));
            self.effectiveness = if stuck { 0.0 } else { 1.0 };
            self.delivered = 0.0;
            self.over = stuck;
        }
    }

    /// Rotor `rotor` is stopped (its ESC says so): out, delivering
    /// nothing, whatever was learned of another.
    pub fn stopped(&mut self, rotor: usize) {
        if self.rotor != Some(rotor) || self.over || self.effectiveness > 0.0 {
            *self = Self {
                rotor: Some(rotor.min(3)),
                ..Self::default()
            };
        }
    }

    /// Forgets the fault (disarmed).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    pub fn rotor(&self) -> Option<usize> {
        self.rotor
    }

    pub fn effectiveness(&self) -> f64 {
        if self.rotor.is_some() {
            self.effectiveness
        } else {
            1.0
        }
    }

    /// One tick: moves what the failed rotor explains of the observer's
    /// wrench `d` into its effectiveness, given `planned`, the delivered
    /// thrust the last command was meant to give. Once the rotor is out
    /// (`out_below`) and commanded nothing, what it explains is thrust it
    /// delivers all the same (stuck, not stopped): learned as such. Returns
    /// the wrench to take out of the observer (zero when nothing moved).
    pub fn learn(
        &mut self,
        body: &TiltedBody,
        d: &Vector6<f64>,
        planned: &Input,
        out_below: f64,
    ) -> Vector6<f64> {
        let Some(i) = self.rotor else {
            return Vector6::zeros();
        };
        let bt = body.thrust_torque.column(i);
        let norm2 = bt[0] * bt[0] + bt[1] * bt[1];
        if norm2 < 1e-12 {
            return Vector6::zeros();
        }
        // Delivered less planned (command fractions) that explains d.
        let delta = (d[3] * bt[0] + d[4] * bt[1]) / norm2;
        let moved = if self.effectiveness < out_below {
            let u = planned[i];
            if !self.over && u > self.delivered + STUCK_BOX {
                // Out for a loss, it is believed to give nothing; the plan
                // that still had it in is no evidence (the observer lags a
                // stopped rotor's loss: learned from it, a stopped rotor
                // was believed to give 0.1-0.2).
                return Vector6::zeros();
            }
            // The plan gave it `planned` (within the box around the last
            // value): what it delivers is that plus delta. A rotor stuck
            // below what was asked of it looks weak until it is out, and
            // is learned here; a stopped one stays at nothing.
            self.delivered = (u + delta).clamp(0.0, 1.0);
            self.delivered - u
        } else {
            let u = planned[i];
            if u < MIN_COMMAND {
                return Vector6::zeros();
            }
            let before = self.effectiveness;
            let learned = before * (1.0 + delta / u);
            self.over |= learned > OVER;
            self.effectiveness = learned.clamp(0.0, 1.0);
            // The part of delta the clamp kept out stays with the observer.
            (self.effectiveness / before - 1.0) * u
        };
        let bf = body.thrust_force.column(i);
        Vector6::new(
            bf[0] * moved,
            bf[1] * moved,
            bf[2] * moved,
            bt[0] * moved,
            bt[1] * moved,
            bt[2] * moved,
        )
    }

    /// The commands to send for the delivered thrust `planned`: the failed
    /// rotor's over its effectiveness (at most 1), zero once it is out
    /// (`out_below`: an effectiveness under this is no rotor to fly on).
    pub fn command(&self, planned: &Input, out_below: f64) -> Input {
        let mut u = *planned;
        if let Some(i) = self.rotor {
            u[i] = if self.effectiveness < out_below {
                0.0
            } else {
                (u[i] / self.effectiveness).clamp(0.0, 1.0)
            };
        }
        u
    }

    /// Each rotor's bounds for the MPC (delivered thrust, min and max):
    /// the failed rotor's up to its effectiveness, once out around what it
    /// still delivers.
    pub fn rotor_bounds(&self, out_below: f64) -> (Input, Input) {
        let mut lo = Input::zeros();
        let mut hi = Input::from_element(1.0);
        if let Some(i) = self.rotor {
            if self.effectiveness < out_below {
                lo[i] = (self.delivered - STUCK_BOX).max(0.0);
                hi[i] = (self.delivered + STUCK_BOX).min(1.0);
            } else {
                hi[i] = self.effectiveness;
            }
        }
        (lo, hi)
    }

    /// What an out rotor still delivers (a fraction of full, whatever it
    /// is commanded; nothing for a stopped one): `None` unless out.
    pub fn out_thrust(&self, out_below: f64) -> Option<f64> {
        self.out(out_below).then_some(self.delivered)
    }

    /// The failed rotor is out: no thrust to fly on.
    pub fn out(&self, out_below: f64) -> bool {
        self.rotor.is_some() && self.effectiveness < out_below
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use atmo_core::{Model, RobotConfig};

    fn body() -> TiltedBody {
        Model::new(&RobotConfig::atmo()).at_tilt(0.3)
    }

    #[test]
    fn each_rotors_lost_thrust_names_that_rotor_even_clipped_at_the_limit() {
        let b = body();
        for i in 0..4 {
            let lost: Vector6<f64> = Vector6::from_iterator(
                b.thrust_force
                    .column(i)
                    .iter()
                    .chain(b.thrust_torque.column(i).iter())
                    .map(|v| -v * 0.4),
            );
            assert_eq!(RotorEstimate::name_rotor(&b, &lost), (i, false));
            let clipped = lost.map(|v| v.clamp(-1.0, 1.0));
            assert_eq!(RotorEstimate::name_rotor(&b, &clipped), (i, false));
            // The same rotor giving more than commanded: a surplus, not a
            // loss on its diagonal partner, even clipped in roll and pitch.
            let surplus = -lost;
            assert_eq!(RotorEstimate::name_rotor(&b, &surplus), (i, true));
            let clipped = surplus.map(|v| v.clamp(-1.0, 1.0));
            assert_eq!(RotorEstimate::name_rotor(&b, &clipped), (i, true));
        }
    }

    #[test]
    fn a_rotor_named_stuck_is_out_and_learns_what_it_delivers() {
        let b = body();
        let mut e = RotorEstimate::default();
        e.start(2, true);
        assert!(e.out(0.5));
        // The MPC plans 0.2 on it, it delivers 0.7: the observer's torque.
        let planned = Input::from_element(0.2);
        let bt = b.thrust_torque.column(2);
        let d = Vector6::new(0.0, 0.0, 0.0, bt[0] * 0.5, bt[1] * 0.5, bt[2] * 0.5);
        let taken = e.learn(&b, &d, &planned, 0.5);
        assert!((e.out_thrust(0.5).unwrap() - 0.7).abs() < 1e-9);
        assert!(
            (taken[3] - d[3]).abs() < 1e-9,
            "what it explains leaves the observer"
        );
        // Commanded nothing, bounded around what it delivers.
        assert_eq!(e.command(&planned, 0.5)[2], 0.0);
        let (lo, hi) = e.rotor_bounds(0.5);
        assert!(lo[2] < 0.7 && hi[2] > 0.7 && hi[2] - lo[2] < 0.05);
        // A rotor named for a loss is not out at once.
        let mut lost = RotorEstimate::default();
        lost.start(2, false);
        assert_eq!(lost.out_thrust(0.5), None);
    }

    #[test]
    fn the_effectiveness_converges_to_what_the_rotor_delivers() {
        let b = body();
        let truth = 0.6;
        let planned = Input::from_element(0.5);
        let mut e = RotorEstimate::default();
        e.start(1, false);
        let mut d = Vector6::zeros();
        for _ in 0..200 {
            // What the observer learns: the rotor, commanded planned / e,
            // delivers truth / e of the plan; a 0.05 gain per update.
            let sent = e.command(&planned, 0.2);
            let delta = truth * sent[1] - planned[1];
            let wrench: Vector6<f64> = Vector6::from_iterator(
                b.thrust_force
                    .column(1)
                    .iter()
                    .chain(b.thrust_torque.column(1).iter())
                    .map(|v| v * delta),
            );
            d += (wrench - d) * 0.05;
            d = d.map(|v| v.clamp(-1.0, 1.0));
            d -= e.learn(&b, &d, &planned, 0.2);
        }
        assert!(
            (e.effectiveness() - truth).abs() < 0.01,
            "{}",
            e.effectiveness()
        );
        assert!(d.fixed_rows::<3>(3).norm() < 0.05, "{d}");
        assert_eq!(e.rotor_bounds(0.2).1[1], e.effectiveness());
        assert!(!e.out(0.2));
    }

    #[test]
    fn nothing_is_learned_before_a_detection_and_an_out_rotor_only_from_plans_without_it() {
        let b = body();
        let mut e = RotorEstimate::default();
        let d = Vector6::from_element(1.0);
        assert_eq!(
            e.learn(&b, &d, &Input::from_element(0.5), 0.2),
            Vector6::zeros()
        );
        assert_eq!(
            e.command(&Input::from_element(0.5), 0.2),
            Input::from_element(0.5)
        );
        e.start(2, false);
        e.effectiveness = 0.1;
        assert!(e.out(0.2));
        assert_eq!(e.command(&Input::from_element(0.5), 0.2)[2], 0.0);
        assert_eq!(e.rotor_bounds(0.2).1[2], STUCK_BOX);
        let column = |k: f64| -> Vector6<f64> {
            Vector6::from_iterator(
                b.thrust_force
                    .column(2)
                    .iter()
                    .chain(b.thrust_torque.column(2).iter())
                    .map(|v| v * k),
            )
        };
        // Out for a loss: the plan that still had it in (0.5) teaches
        // nothing, whatever the observer holds (a stopped rotor's loss
        // is still being learned there).
        let lagging = column(-0.3);
        assert_eq!(
            e.learn(&b, &lagging, &Input::from_element(0.5), 0.2),
            Vector6::zeros()
        );
        assert_eq!(e.out_thrust(0.2), Some(0.0));
        // Planned out, a loss left in the observer: it gives nothing.
        e.learn(&b, &lagging, &Input::zeros(), 0.2);
        assert_eq!(e.out_thrust(0.2), Some(0.0));
        // Planned out, the observer sees it deliver 0.4: stuck below what
        // was asked (it looked weak), learned.
        let given = column(0.4);
        let taken = e.learn(&b, &given, &Input::zeros(), 0.2);
        assert!((taken - given).norm() < 1e-9);
        assert!((e.out_thrust(0.2).unwrap() - 0.4).abs() < 1e-9);
        let (lo, hi) = e.rotor_bounds(0.2);
        assert!((lo[2] - 0.39).abs() < 1e-9 && (hi[2] - 0.41).abs() < 1e-9);
        // Seen over its command, out: learned from any plan (named stuck).
        let mut stuck = RotorEstimate::default();
        stuck.start(2, true);
        stuck.learn(&b, &column(-0.1), &Input::from_element(0.5), 0.2);
        assert!((stuck.out_thrust(0.2).unwrap() - 0.4).abs() < 1e-9);
    }
}
