//! `[effects.ground_contact]`: the contact law's parameters and defaults.

/// Largest contact stiffness the plant resolves at its largest step, N/m
/// (see the check in `super::EffectsConfig`'s validation).
pub const MAX_CONTACT_STIFFNESS: f64 = 1e6;

atmo_core::params! {
    /// `[effects.ground_contact]`: compliant wheel contacts, wheel drive, and
    /// crash detection (see [`crate::contact`] for the law).
    #[derive(Debug, Clone, PartialEq)]
    pub struct GroundContactConfig: Default {
        /// Whether the wheels and the base touch the ground.
        pub enabled: bool = true;
        /// Normal stiffness per contact point. Stiffer than 1e6 N/m a
        /// contact is no longer resolved by the RK4 step (omega dt =
        /// sqrt(k / m) dt passes 0.85 for a wheel carrying a quarter of
        /// 5.5 kg at dt = 1 ms).
        pub stiffness: f64 = 20000.0, range 1.0..=MAX_CONTACT_STIFFNESS, unit "N/m";
        /// Normal damping per contact point.
        pub damping: f64 = 200.0, range 0.0..=1e6, unit "N s/m";
        /// Coulomb friction coefficient (body points, and wheels when rolling).
        pub friction: f64 = 0.8, range 0.0..=3.0;
        /// Coulomb friction coefficient of a wheel sliding sideways.
        pub lateral_friction: f64 = 0.45, range 0.01..=3.0;
        /// Tangential (stiction) spring per contact point.
        pub tangential_stiffness: f64 = 5000.0, range 1.0..=MAX_CONTACT_STIFFNESS, unit "N/m";
        /// Tangential damping per contact point.
        pub tangential_damping: f64 = 100.0, range 0.0..=1e6, unit "N s/m";
        /// Spin inertia of one side's drive (two wheels on a belt).
        pub wheel_inertia: f64 = 0.01, range 1e-6..=100.0, unit "kg m^2";
        /// Proportional gain of each side's speed controller.
        pub wheel_kp: f64 = 0.5, range 0.0..=1e3, unit "N m s/rad";
        /// Integral gain of each side's speed controller.
        pub wheel_ki: f64 = 10.0, range 0.0..=1e4, unit "N m/rad";
        /// Torque limit of each side's drive motor.
        pub wheel_torque_max: f64 = 3.0, range 1e-3..=1e4, unit "N m";
        /// The base box (body frame, relative to B): lower corner.
        pub base_box_min: [f64; 3] = [-0.10, -0.06, -0.05], range Finite, unit "m";
        /// The base box: upper corner, each entry above `base_box_min`'s.
        pub base_box_max: [f64; 3] = [0.10, 0.06, 0.06], range Finite, unit "m";
        /// A wheel hitting the ground faster than this is a crash.
        pub crash_speed: f64 = 2.0, range 1e-2..=100.0, unit "m/s";
        /// Tilt of the body z axis from the ground normal, while touching
        /// the ground, beyond which the robot has tipped over.
        pub tip_over_deg: f64 = 60.0, range 1.0..=180.0, unit "deg";
    }
    check |contact, c, prefix| {
        if (0..3).any(|k| contact.base_box_min[k] >= contact.base_box_max[k]) {
            return Err(c.fail(
                &atmo_core::params::key(prefix, "base_box_max"),
                "each entry above base_box_min",
                format!("{:?}", contact.base_box_max),
            ));
        }
        Ok(())
    }
}
