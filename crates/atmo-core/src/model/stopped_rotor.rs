//! The allocation with one rotor stopped: the three rotors left, the
//! stopped rotor's diagonal partner only pushing (`FailsafeControl::Backup`
//! in atmo-flight flies it).

use nalgebra::{Matrix3, Vector2, Vector3};

use super::{Input, TiltedBody};

impl TiltedBody {
    /// As [`Self::commands_for`] with rotor `stopped` delivering only
    /// `delivered` (a fraction of full thrust: what its ESC says is left):
    /// the commands of the other three for the body z force `force_z` and
    /// as much of the roll and pitch torque of `torque` as they can give.
    /// The yaw is not held (three rotors cannot hold it and the lift and
    /// level together: Mueller and D'Andrea's relaxed hover lets it spin).
    ///
    /// The stopped rotor's diagonal partner (the rotor whose roll and pitch
    /// torque points most against its) can only push: where the three
    /// would need it below zero it is off, and the pair left on the other
    /// diagonal gives the force exactly and, of the torque, its component
    /// about the one axis a diagonal pair can turn (about the pair's own
    /// diagonal nothing can; a spinning body turns that axis round, which
    /// is what keeps it level on average). The stopped rotor's command is
    /// 0. Unclamped above; +inf in every entry when no allocation exists.
    pub fn commands_without(
        &self,
        stopped: usize,
        delivered: f64,
        force_z: f64,
        torque: &Vector3<f64>,
    ) -> Input {
        let stopped = stopped.min(3);
        // Rows F_z, tau_x, tau_y of each rotor's thrust at full command.
        let column = |i: usize| {
            Vector3::new(
                self.thrust_force[(2, i)],
                self.thrust_torque[(0, i)],
                self.thrust_torque[(1, i)],
            )
        };
        // The yaw row is left out: three rotors cannot hold it too.
        let rhs = self.thrust_wrench_for(force_z, torque).xyz() - column(stopped) * delivered;
        let others = others_than(stopped);
        let (partner, a, b) = self.diagonals(stopped);
        let mut u = Input::zeros();
        let three =
            Matrix3::from_columns(&[column(others[0]), column(others[1]), column(others[2])]);
        if let Some(f) = three.lu().solve(&rhs)
            && others
                .iter()
                .zip(f.iter())
                .all(|(&r, &v)| r != partner || v >= 0.0)
        {
            for (&r, &v) in others.iter().zip(f.iter()) {
                u[r] = v;
            }
            return u;
        }
        // The partner off: the pair gives F_z exactly, f = f0 + s n along
        // the line of that force, s the least-squares torque.
        let (ca, cb) = (column(a), column(b));
        let force_norm = ca.x * ca.x + cb.x * cb.x;
        if force_norm <= f64::EPSILON {
            return Input::from_element(f64::INFINITY);
        }
        let f0 = nalgebra::Vector2::new(ca.x, cb.x) * (rhs.x / force_norm);
        let n = nalgebra::Vector2::new(cb.x, -ca.x);
        let torque_of =
            |f: &nalgebra::Vector2<f64>| ca.fixed_rows::<2>(1) * f.x + cb.fixed_rows::<2>(1) * f.y;
        let turn = torque_of(&n);
        let miss = torque_of(&f0) - rhs.fixed_rows::<2>(1);
        let s = if turn.norm_squared() > f64::EPSILON {
            -turn.dot(&miss) / turn.norm_squared()
        } else {
            0.0
        };
        let f = f0 + n * s;
        u[a] = f.x;
        u[b] = f.y;
        u
    }

    /// The roll and pitch torque of rotor `rotor` (0-based) at full
    /// command, N m: the one axis it turns the body about, and how hard.
    pub fn roll_pitch_lever(&self, rotor: usize) -> Vector2<f64> {
        self.thrust_torque.fixed_view::<2, 1>(0, rotor).into_owned()
    }

    /// With rotor `stopped` out: its diagonal partner (the rotor whose roll
    /// and pitch torque points most against its) and the pair on the other
    /// diagonal, in order.
    pub fn diagonals(&self, stopped: usize) -> (usize, usize, usize) {
        let stopped = stopped.min(3);
        let others = others_than(stopped);
        let against = |i: usize| {
            self.roll_pitch_lever(i)
                .dot(&self.roll_pitch_lever(stopped))
        };
        let partner = others
            .into_iter()
            .min_by(|&a, &b| against(a).total_cmp(&against(b)))
            .unwrap_or(others[0]);
        let mut pair = others.into_iter().filter(|&r| r != partner);
        let a = pair.next().unwrap_or(others[0]);
        let b = pair.next().unwrap_or(others[1]);
        (partner, a, b)
    }
}

/// The three rotor indices other than `i`, in order.
fn others_than(i: usize) -> [usize; 3] {
    let mut out = [0; 3];
    for (slot, r) in out.iter_mut().zip((0..4).filter(|&r| r != i)) {
        *slot = r;
    }
    out
}
