//! The step: what `Plant::step` runs, once per `dt`.
//!
//! # The AVX2 rule
//!
//! `Plant::step` (in `plant/mod.rs`) holds two copies of this code: the
//! portable one (`step_kernel` called directly) and `step_avx2`, the same
//! call compiled with `#[target_feature(enable = "avx2,fma")]`. A function
//! gets the AVX2 instructions only where it is inlined into `step_avx2`;
//! anything called out of line runs its portable code in both copies. So
//! every function of the step modules (this file, `plant/effects.rs`,
//! `contact.rs`, `body.rs`, `ground_effect.rs`) says how it is compiled:
//! `#[inline(always)]` (it enters both copies), or `#[inline(never)]` for a
//! path that is out of line on purpose (rare: event bookkeeping, a body
//! rebuilt when the tilt stops, code outside the step). A plain `fn` there
//! is an error: the test `tests/avx2_rule.rs` reads these files and lists
//! every function with neither attribute.
//!
//! The two copies give bit-identical results: Rust never fuses a multiply
//! and an add on its own (FMA only through `mul_add`, which the plant does
//! not call), and vectorizing the lane loops does not reorder any sum. The
//! atmo-sim test `the_avx2_step_code_gives_the_portable_code_s_trajectory_bit_for_bit`
//! flies each scenario with both copies and compares the trajectories.
//!
//! # One step
//!
//! The tilt moves by the limited command (`update_body`), the random
//! processes advance, RK4 integrates the continuous state (`derivative_into`,
//! four stages over the entries that can change: `Reach`), then `observe`
//! holds the contact springs, reports contacts and events and samples the
//! sensors.

use std::borrow::Cow;

use atmo_core::control::WheelRates;
use atmo_core::model::{Input, State, idx};
use nalgebra::{Matrix3, Vector3, Vector6};

use super::effects::drag_wrench;
use super::{
    Command, ContactInfo, CrashKind, ENERGY, EVENT_CAPACITY, Event, EventKind, Ext, N_CONTACTS,
    N_EXT, N_WHEELS, Plant, SPRING, THRUST, TILT_GRID, WHEEL, WHEEL_INT,
};
use atmo_core::model::{Attitude, state_derivative_at};

use crate::body::{accelerations, effective_body, lerp_body};
use crate::contact::{Pose, SPIN_SIGN, WHEEL_SIDE, WheelLanes};
use crate::error::{PlantError, Result};

/// Which contact points a step has to consider (see `Plant::reachable`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Reach {
    Nothing,
    Wheels,
    Everything,
}

impl Reach {
    /// How many leading entries of the continuous state can change.
    #[inline(always)]
    fn state_len(self) -> usize {
        match self {
            Self::Nothing => SPRING,
            Self::Wheels => SPRING + 3 * N_WHEELS,
            Self::Everything => N_EXT,
        }
    }
}

impl Plant {
    // The accessors the step uses, here so that they are step code.

    /// s, simulated time (step count times dt).
    #[inline(always)]
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.dt
    }

    /// The true rigid-body state.
    #[inline(always)]
    pub fn state(&self) -> State {
        body_state(&self.ext)
    }

    /// The ground-contact signal the robot reports.
    #[inline(always)]
    pub fn contact_signal(&self) -> bool {
        let wheel_force: f64 = self.contacts[..N_WHEELS]
            .iter()
            .map(|c| c.normal_force)
            .sum();
        self.mocap.contact_signal(wheel_force)
    }

    /// `x_dot` of the rigid body now under `command` (with every effect;
    /// ground-effect and wind noise as held for the current step).
    #[inline(never)] // not step code
    pub fn body_derivative(&self, command: &Command) -> Result<State> {
        let cmd = self.sanitize(command)?;
        let d = self.derivative(&self.ext, &cmd, self.reachable());
        Ok(d.fixed_rows::<12>(0).into_owned())
    }

    #[inline(always)]
    fn sanitize(&self, command: &Command) -> Result<Command> {
        for (i, u) in command.rotors.iter().enumerate() {
            if !u.is_finite() {
                const NAMES: [&str; 4] = ["rotors[0]", "rotors[1]", "rotors[2]", "rotors[3]"];
                return Err(PlantError::NonFiniteCommand {
                    name: NAMES[i],
                    value: *u,
                });
            }
        }
        for (name, v) in [
            ("tilt_rate", command.tilt_rate),
            ("wheel_rates.left", command.wheel_rates.left),
            ("wheel_rates.right", command.wheel_rates.right),
        ] {
            if !v.is_finite() {
                return Err(PlantError::NonFiniteCommand { name, value: v });
            }
        }
        let wmax = self.wheel_rate_max;
        Ok(Command {
            rotors: Input::new(
                command.rotors[0].clamp(0.0, 1.0),
                command.rotors[1].clamp(0.0, 1.0),
                command.rotors[2].clamp(0.0, 1.0),
                command.rotors[3].clamp(0.0, 1.0),
            ),
            tilt_rate: command
                .tilt_rate
                .clamp(-self.tilt_rate_max, self.tilt_rate_max),
            wheel_rates: WheelRates {
                left: command.wheel_rates.left.clamp(-wmax, wmax),
                right: command.wheel_rates.right.clamp(-wmax, wmax),
            },
        })
    }

    /// The step; it and everything it calls per step are `inline(always)`
    /// so that both copies of `step` contain all of it.
    #[inline(always)]
    pub(super) fn step_kernel(&mut self, command: &Command) -> Result<()> {
        let cmd = self.sanitize(command)?;
        self.command = cmd;
        let dt = self.dt;

        // Tilt: self-locking screw, moves only by the (limited) command.
        let new_tilt = (self.tilt + cmd.tilt_rate * dt).clamp(0.0, self.tilt_max);
        self.update_body(0.5 * (self.tilt + new_tilt), new_tilt != self.tilt);

        // Random processes, held over the step.
        if self.ground_effect.is_some() {
            for n in &mut self.ge_noise {
                n.advance(&mut self.ge_rng);
            }
        }
        let mid_time = self.time() + 0.5 * dt;
        if let Some(w) = &mut self.wind {
            for n in &mut w.turbulence {
                n.advance(&mut w.rng);
            }
            self.wind_now = w.at(mid_time);
        }

        // RK4 over the states that can change in this step: the contact
        // springs of points that cannot reach the ground are zero (reset
        // when a contact opens) and their derivatives are zero, so they are
        // left out, exactly (same operations, element by element, on the rest).
        let reach = self.reachable();
        let n = reach.state_len();
        self.prepare_wheel_lanes(reach);
        // One call site for the four stages (the derivative is inlined, once):
        // stage s+1 is evaluated at x + k_s h_s, and the weighted sum
        // k1 + 2 k2 + 2 k3 + k4 is accumulated in that order. Only the first
        // n entries are touched: no copies of the whole state.
        let x = &self.ext;
        let half = 0.5 * dt;
        let stage_step = [half, half, dt];
        let weight = [1.0, 2.0, 2.0, 1.0];
        let mut stage = *x;
        let mut k = Ext::from([0.0; N_EXT]);
        let mut sum = [0.0; N_EXT];
        // Slices of the live length: bounds checked once, so the loops vectorize.
        let x = &x.as_slice()[..n];
        for s in 0..4 {
            self.derivative_into(&stage, &cmd, reach, &mut k);
            let k = &k.as_slice()[..n];
            if s == 0 {
                sum[..n].copy_from_slice(k);
            } else {
                for (sum, k) in sum[..n].iter_mut().zip(k) {
                    *sum += k * weight[s];
                }
            }
            if s < 3 {
                let h = stage_step[s];
                for ((st, x), k) in stage.as_mut_slice()[..n].iter_mut().zip(x).zip(k) {
                    *st = x + k * h;
                }
            }
        }
        let sixth = dt / 6.0;
        let next = &mut stage.as_mut_slice()[..n];
        for ((next, x), sum) in next.iter_mut().zip(x).zip(&sum[..n]) {
            *next = x + sum * sixth;
        }
        if !next.iter().all(|v| v.is_finite()) {
            return Err(PlantError::Diverged {
                time: self.time() + dt,
            });
        }
        self.ext.as_mut_slice()[..n].copy_from_slice(next);
        self.tilt = new_tilt;
        self.steps += 1;
        self.observe();
        Ok(())
    }

    /// Sets the composite body for a step whose mid-step tilt is `mid`:
    /// exact (atmo-core's `at_tilt` with the mass errors) while the tilt
    /// stands still; while it moves, interpolated between the exact bodies
    /// of the 0.25 deg grid built at start-up, so that morphing does not
    /// rebuild and refactor the body every step.
    #[inline(always)]
    pub(super) fn update_body(&mut self, mid: f64, moving: bool) {
        if moving {
            let cells = self.tilt_grid.len() - 1;
            let k = ((mid / TILT_GRID).floor().max(0.0) as usize).min(cells - 1);
            let (lo, hi) = (&self.tilt_grid[k], &self.tilt_grid[k + 1]);
            let w = ((mid - lo.varphi) / (hi.varphi - lo.varphi)).clamp(0.0, 1.0);
            self.body = lerp_body(lo, hi, w, mid);
            self.body_interpolated = true;
        } else if mid != self.body.varphi || self.body_interpolated {
            if let Some(b) = effective_body(&self.model, mid, self.mass_error, self.com_offset) {
                self.body = b;
                self.body_interpolated = false;
            }
        } else {
            return; // the same body: the ground-effect slice and wheel lanes stand too
        }
        self.wheel_lanes = None;
        if let Some(ge) = &self.ground_effect {
            self.ge_slice = ge.slice(self.body.varphi);
        }
    }

    /// After a step: contact springs, drive integrators, contact report,
    /// events, sensors.
    #[inline(always)]
    pub(super) fn observe(&mut self) {
        let mut report = [ContactInfo::default(); N_CONTACTS];
        // Far above the ground nothing touches: skip the contact pass.
        let reach = self.reachable();
        let near = reach != Reach::Nothing;
        let rot = if near {
            let x = body_state(&self.ext);
            Attitude::of(&x).r
        } else {
            Matrix3::identity()
        };
        let mut wheel_springs = [[0.0; 4]; 3];
        self.prepare_wheel_lanes(reach);
        if near {
            (report, wheel_springs) = self.contact_report(&rot, reach == Reach::Everything);
        }
        let time = self.time();
        let mut new_events: [Option<EventKind>; N_CONTACTS + 1] = [None; N_CONTACTS + 1];
        if let Some((law, drive, cfg)) = &self.contact {
            let n = self.plane.normal;
            // Out of reach nothing touches: the springs only need zeroing if
            // something touched a step ago (they stay zero otherwise).
            if near || self.contacts.iter().any(|c| c.touching) {
                for j in 0..N_WHEELS {
                    for k in 0..3 {
                        self.ext[SPRING + 3 * j + k] = wheel_springs[k][j];
                    }
                }
                for (j, info) in report.iter().enumerate().skip(N_WHEELS) {
                    let s = if info.touching {
                        let s = Vector3::new(
                            self.ext[SPRING + 3 * j],
                            self.ext[SPRING + 3 * j + 1],
                            self.ext[SPRING + 3 * j + 2],
                        );
                        law.limit_spring(&n, &s, info.normal_force, None)
                    } else {
                        Vector3::zeros()
                    };
                    self.ext.fixed_rows_mut::<3>(SPRING + 3 * j).copy_from(&s);
                }
            }
            if drive.ki > 0.0 {
                let limit = drive.torque_max / drive.ki;
                for side in 0..2 {
                    self.ext[WHEEL_INT + side] = self.ext[WHEEL_INT + side].clamp(-limit, limit);
                }
            }
            // Crash reports (a touchdown needs a touching point: only when near).
            if near {
                let crash_speed = cfg.crash_speed;
                for j in 0..N_CONTACTS {
                    let was = self.contacts[j].touching;
                    let now = &report[j];
                    if now.touching && !was {
                        // The speed just before contact: the first touching step
                        // has already been slowed by the contact force.
                        let speed = now.approach_speed.max(self.contacts[j].approach_speed);
                        if j < N_WHEELS {
                            if speed > crash_speed {
                                new_events[j] = Some(EventKind::Crash(CrashKind::HardImpact {
                                    wheel: j,
                                    speed,
                                }));
                            }
                        } else {
                            new_events[j] = Some(EventKind::Crash(CrashKind::BodyContact {
                                corner: j - N_WHEELS,
                            }));
                        }
                    }
                }
            }
            if !self.tipped && report.iter().any(|c| c.touching) {
                let body_down = rot.column(2).into_owned();
                let cos_angle = (-body_down.dot(&n)).clamp(-1.0, 1.0);
                // Compare cosines (acos only when it tips: once per run).
                if cos_angle < self.tip_over_cos {
                    let angle = cos_angle.acos().to_degrees();
                    self.tipped = true;
                    new_events[N_CONTACTS] =
                        Some(EventKind::Crash(CrashKind::TipOver { angle_deg: angle }));
                }
            }
        }
        for kind in new_events.into_iter().flatten() {
            self.push_event(Event { time, kind });
        }
        self.contacts = report;
        let grounded = self.contact_signal();
        if grounded != self.grounded {
            self.grounded = grounded;
            let kind = if grounded {
                EventKind::Touchdown
            } else {
                EventKind::Liftoff
            };
            self.push_event(Event { time, kind });
        }
        let x = self.state();
        self.mocap.record(self.steps, &x);
    }

    #[inline(never)] // rare: a few events per run
    fn push_event(&mut self, event: Event) {
        if matches!(event.kind, EventKind::Crash(_)) && self.crash.is_none() {
            self.crash = Some(event);
        }
        if self.events.len() < EVENT_CAPACITY {
            self.events.push(event);
        } else {
            self.events_dropped += 1;
        }
    }

    /// Makes the current body's wheel lanes if a wheel may reach the ground
    /// and they are not made yet (the body changed since).
    #[inline(always)]
    fn prepare_wheel_lanes(&mut self, reach: Reach) {
        if reach != Reach::Nothing && self.wheel_lanes.is_none() {
            self.wheel_lanes = Some(WheelLanes::of(&self.body, self.wheel_radius));
        }
    }

    /// The current body's wheel lanes; made here only if they were not
    /// prepared (`body_derivative` right after the body changed).
    #[inline(always)]
    fn wheel_lanes(&self) -> Cow<'_, WheelLanes> {
        self.wheel_lanes.as_ref().map_or_else(
            || Cow::Owned(WheelLanes::of(&self.body, self.wheel_radius)),
            Cow::Borrowed,
        )
    }

    /// Which contact points can touch the ground during the coming step,
    /// from where B is now: `reach` and `corner_reach` carry a 5 cm margin
    /// that no point covers in one step below 50 m/s.
    #[inline(always)]
    fn reachable(&self) -> Reach {
        if self.contact.is_none() {
            return Reach::Nothing;
        }
        let height = self.plane.height(&Vector3::new(
            self.ext[idx::X],
            self.ext[idx::Y],
            self.ext[idx::Z],
        ));
        if height > self.reach {
            Reach::Nothing
        } else if height > self.corner_reach {
            Reach::Wheels
        } else {
            Reach::Everything
        }
    }

    /// `max_k down_b . c_k` over the base-box corners (body frame): the
    /// support function of the axis-aligned box, one term per axis.
    #[inline(always)]
    fn box_support(&self, down_b: &Vector3<f64>) -> f64 {
        let (lo, hi) = (&self.corners[0], &self.corners[7]);
        (0..3)
            .map(|i| (down_b[i] * lo[i]).max(down_b[i] * hi[i]))
            .sum()
    }

    /// Where each contact point is after a step: touching or not, its speed
    /// towards the ground and its normal force (the contact law's normal
    /// part; wheel spin moves the rim point along the ground, not into it);
    /// and the wheels' tangential springs held at the friction limit. The
    /// corners are left out (not touching) unless `corners_in_reach`.
    #[inline(always)]
    fn contact_report(
        &self,
        r: &Matrix3<f64>,
        corners_in_reach: bool,
    ) -> ([ContactInfo; N_CONTACTS], [[f64; 4]; 3]) {
        let mut report = [ContactInfo::default(); N_CONTACTS];
        let Some((law, _, _)) = &self.contact else {
            return (report, [[0.0; 4]; 3]);
        };
        let ext = &self.ext;
        let p = Vector3::new(ext[idx::X], ext[idx::Y], ext[idx::Z]);
        let v = Vector3::new(ext[idx::VX], ext[idx::VY], ext[idx::VZ]);
        let w = Vector3::new(ext[idx::WX], ext[idx::WY], ext[idx::WZ]);
        let n = self.plane.normal;
        let down_b = -(r.transpose() * n);
        let height = self.plane.height(&p);
        let v_n_b = v.dot(&n);
        let pose = Pose {
            r,
            normal: n,
            down: down_b,
            height,
            v,
            w,
        };
        let wheels = self
            .wheel_lanes()
            .report(&pose, law, &wheel_springs(&self.ext));
        for (j, info) in report[..N_WHEELS].iter_mut().enumerate() {
            *info = ContactInfo {
                normal_force: wheels.normal_force[j],
                approach_speed: wheels.approach_speed[j],
                touching: wheels.touching[j],
            };
        }
        if !corners_in_reach {
            return (report, wheels.spring);
        }
        // The corners in plain arrays first (a loop that vectorizes), then
        // into the report.
        let mut depth = [0.0; 8];
        let mut v_n = [0.0; 8];
        // (v + R (w x c)) . n = v . n - down_b . (w x c) = v . n - c . (down_b x w),
        // with R^T n = -down_b.
        let down_x_w = down_b.cross(&w);
        for (k, c) in self.corners.iter().enumerate() {
            depth[k] = down_b.dot(c) - height;
            v_n[k] = v_n_b - c.dot(&down_x_w);
        }
        for (k, info) in report[N_WHEELS..].iter_mut().enumerate() {
            info.approach_speed = -v_n[k];
            if depth[k] > 0.0 {
                info.touching = true;
                info.normal_force = law.normal_force(depth[k], v_n[k]);
            }
        }
        (report, wheels.spring)
    }

    /// Contact wrench on the body (body force, torque about B) and the
    /// derivatives of the contact springs and wheel drives, written into `d`.
    /// Skips the contact points when B is farther from the ground than any
    /// point of the robot can reach.
    #[inline(always)]
    fn contact_terms(
        &self,
        ext: &Ext,
        r: &Matrix3<f64>,
        cmd: &Command,
        reach: Reach,
        d: &mut Ext,
    ) -> Vector6<f64> {
        let Some((law, drive, _)) = &self.contact else {
            return Vector6::zeros();
        };
        let body = &self.body;
        let p = Vector3::new(ext[idx::X], ext[idx::Y], ext[idx::Z]);
        let v = Vector3::new(ext[idx::VX], ext[idx::VY], ext[idx::VZ]);
        let w = Vector3::new(ext[idx::WX], ext[idx::WY], ext[idx::WZ]);
        let height = self.plane.height(&p);
        let rt = r.transpose();
        let n = self.plane.normal;
        let down_b = -(rt * n);
        let mut force = Vector3::zeros();
        let mut torque = Vector3::zeros();
        let mut wheel_torque = [0.0; 2];
        let spin = [ext[WHEEL], ext[WHEEL + 1]];
        // A rim point is at most the radius below its hub: while every hub
        // is higher than that, no wheel touches (the usual case in flight).
        let wheel_may_touch = reach != Reach::Nothing
            && body
                .rotor_position
                .iter()
                .any(|c| down_b.dot(c) + self.wheel_radius > height);
        if wheel_may_touch {
            let pose = Pose {
                r,
                normal: n,
                down: down_b,
                height,
                v,
                w,
            };
            let spin: [f64; 4] = std::array::from_fn(|j| spin[WHEEL_SIDE[j]]);
            let wheels = self
                .wheel_lanes()
                .forces(&pose, law, &spin, &wheel_springs(ext));
            for j in 0..N_WHEELS {
                if !wheels.touching[j] {
                    continue;
                }
                for k in 0..3 {
                    d[SPRING + 3 * j + k] = wheels.spring_rate[k][j];
                }
                force += Vector3::new(wheels.force[0][j], wheels.force[1][j], wheels.force[2][j]);
                torque += Vector3::new(
                    wheels.torque[0][j],
                    wheels.torque[1][j],
                    wheels.torque[2][j],
                );
                wheel_torque[WHEEL_SIDE[j]] += wheels.axial[j];
            }
        }
        // The base-box corners: none touches while the box's support along
        // down_b is below B (a point c is `height - down_b . c` above ground).
        if reach == Reach::Everything && self.box_support(&down_b) > height {
            for (k, point) in self.corners.iter().enumerate() {
                let j = N_WHEELS + k;
                let depth = down_b.dot(point) - height;
                if depth <= 0.0 {
                    continue;
                }
                let v_point = v + r * w.cross(point);
                let s = Vector3::new(
                    ext[SPRING + 3 * j],
                    ext[SPRING + 3 * j + 1],
                    ext[SPRING + 3 * j + 2],
                );
                let (f_world, _, s_dot) = law.force(&n, depth, &v_point, &s, None);
                d.fixed_rows_mut::<3>(SPRING + 3 * j).copy_from(&s_dot);
                let f_b = rt * f_world;
                force += f_b;
                torque += point.cross(&f_b);
            }
        }
        // Wheel drives: PI speed control with a torque limit; the
        // motor reaction acts on the body about the side's spin axis.
        let cmd_rates = [cmd.wheel_rates.left, cmd.wheel_rates.right];
        let side_axis = [
            body.rotor_axis[1] * SPIN_SIGN[1],
            body.rotor_axis[0] * SPIN_SIGN[0],
        ];
        for side in 0..2 {
            let err = cmd_rates[side] - spin[side];
            let tau = (drive.kp * err + drive.ki * ext[WHEEL_INT + side])
                .clamp(-drive.torque_max, drive.torque_max);
            d[WHEEL + side] = (tau + wheel_torque[side]) / drive.inertia;
            d[WHEEL_INT + side] = err;
            torque -= side_axis[side] * tau;
        }
        Vector6::new(force.x, force.y, force.z, torque.x, torque.y, torque.z)
    }

    /// The derivative of the continuous state.
    #[inline(never)] // for `body_derivative`, not the step
    fn derivative(&self, ext: &Ext, cmd: &Command, reach: Reach) -> Ext {
        let mut d = Ext::zeros();
        self.derivative_into(ext, cmd, reach, &mut d);
        d
    }

    /// The derivative of the continuous state, written into the first
    /// `reach.state_len()` entries of `d` (the only ones that can be
    /// nonzero; the rest is left as it is).
    #[inline(always)]
    fn derivative_into(&self, ext: &Ext, cmd: &Command, reach: Reach, d: &mut Ext) {
        let body = &self.body;
        let x = body_state(ext);
        let att = Attitude::of(&x);
        d.as_mut_slice()[..reach.state_len()].fill(0.0);

        // Rotor thrust: motor lag and curve, battery, ground effect.
        let mut t = cmd.rotors;
        if let Some((tau, f)) = self.motor_lag {
            for i in 0..4 {
                let u = cmd.rotors[i];
                let target = (1.0 - f) * u + f * u * u;
                t[i] = ext[THRUST + i];
                d[THRUST + i] = (target - t[i]) / tau;
            }
        } else if let Some(f) = self.thrust_curve {
            t = t.map(|u| crate::motor::ThrustCurveConfig::thrust(f, u));
        }
        let mut u_eff = t;
        if let Some(b) = &self.battery {
            let used = b.used_wh * 3600.0 + ext[ENERGY];
            let scale = 1.0 - b.sag * (used / (b.capacity_wh * 3600.0)).min(1.0);
            u_eff *= scale;
            d[ENERGY] = t
                .iter()
                .map(|ti| {
                    let ti = ti.max(0.0);
                    b.full_power_w * ti * ti.sqrt()
                })
                .sum();
        }

        let pushed = self.external.0 != Vector3::zeros() || self.external.1 != Vector3::zeros();
        let needs_pose =
            pushed || self.ground_effect.is_some() || self.drag.is_some() || self.contact.is_some();
        let mut extra = Vector6::zeros();
        if needs_pose {
            let r = att.r;
            if pushed {
                let f = r.transpose() * self.external.0;
                let t = &self.external.1;
                extra += Vector6::new(f.x, f.y, f.z, t.x, t.y, t.z);
            }
            let p = Vector3::new(x[idx::X], x[idx::Y], x[idx::Z]);
            let v = Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]);
            let w = Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]);

            if let Some(ge) = &self.ground_effect {
                for i in 0..4 {
                    // No thrust, no gain to apply (the common case on the ground).
                    if u_eff[i] == 0.0 {
                        continue;
                    }
                    let hub = p + r * body.rotor_position[i];
                    let h = self.plane.height(&hub);
                    u_eff[i] *= 1.0 + ge.sample(&self.ge_slice, h, self.ge_noise[i].value);
                }
            }

            if let Some(drag) = &self.drag {
                // The body drag acts at the airframe's centre of mass (the
                // robot file's geometry at this tilt): a CoM offset moves
                // the mass, not the shape the air flows around.
                let centre = body.first_moment / body.mass - self.com_offset.unwrap_or_default();
                extra += drag_wrench(drag, body, &centre, &r, &(v - self.wind_now), &w, &t);
            }

            if self.contact.is_some() {
                extra += self.contact_terms(ext, &r, cmd, reach, d);
            }
        }

        if let Some(tilt) = &self.thrust_axis {
            let f = tilt.cross(&(body.thrust_force * u_eff));
            extra += Vector6::new(f.x, f.y, f.z, 0.0, 0.0, 0.0);
        }

        let acc = accelerations(body, &x, &att, &u_eff, &extra);
        d.fixed_rows_mut::<12>(0)
            .copy_from(&state_derivative_at(&x, &att, &acc));
    }
}

/// The tangential springs of the four wheels, `[component][wheel]`.
#[inline(always)]
fn wheel_springs(ext: &Ext) -> [[f64; 4]; 3] {
    std::array::from_fn(|k| std::array::from_fn(|j| ext[SPRING + 3 * j + k]))
}

/// The 12 rigid-body states at the head of the plant's state (a plain copy;
/// nalgebra's `into_owned` goes through a generic iterator).
#[inline(always)]
fn body_state(ext: &Ext) -> State {
    State::from_column_slice(&ext.as_slice()[..12])
}
