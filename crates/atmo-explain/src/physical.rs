//! The selected effects' coefficients as physical parameters, and those as
//! a plant file (`fitted_effects.toml`, the plant's `[effects.<name>]`
//! sections).

use std::fmt::Write as _;

use atmo_core::config::ArmInertiaConvention;
use atmo_core::ground_effect::table::GroundEffectConfig;
use nalgebra::DVector;

use crate::effects::{self, DRAG_WIDTH, Effect, GE_HEIGHTS, Layout};

/// Tilt step (deg) of the table a fitted ground effect is written as.
const PLANT_TILT_STEP_DEG: f64 = 5.0;
/// Rows of that table past the first (0 to 90 deg).
const PLANT_TILT_ROWS: usize = (90.0 / PLANT_TILT_STEP_DEG) as usize;

/// The robot file's name of an arm-inertia convention.
pub(crate) fn convention_name(c: ArmInertiaConvention) -> &'static str {
    match c {
        ArmInertiaConvention::AuthorsModel => "authors_model",
        ArmInertiaConvention::AboutCom => "about_com",
    }
}

/// Physical parameters of the selected effects, from the coefficients.
#[derive(Debug, Clone, Default)]
pub(crate) struct Physical {
    pub(crate) ge: Option<Vec<f64>>,
    pub(crate) tau: Option<f64>,
    pub(crate) drag: Option<[f64; DRAG_WIDTH]>,
    pub(crate) wind: Option<[f64; 2]>,
    pub(crate) thrust_scale: Option<f64>,
    pub(crate) thrust_curve: Option<f64>,
    pub(crate) battery: Option<f64>,
    pub(crate) com: Option<[f64; 2]>,
    pub(crate) thrust_axis: Option<[f64; 2]>,
    pub(crate) inertia: Option<f64>,
    pub(crate) mass: Option<f64>,
}

/// Battery of the written `battery_sag` section: capacity (Wh) and the
/// power per rotor at full command (W) the fitted loss is expressed with.
pub(crate) const BATTERY_CAPACITY_WH: f64 = 110.0;
pub(crate) const BATTERY_FULL_POWER_W: f64 = 560.0;

impl Physical {
    pub(crate) fn from_theta(
        layout: &Layout,
        set: &[Effect],
        idx: &[usize],
        theta: &DVector<f64>,
        tau: f64,
    ) -> Self {
        let get = |e: Effect| -> Vec<f64> {
            layout
                .columns(e)
                .map(|c| idx.iter().position(|i| *i == c).map_or(0.0, |p| theta[p]))
                .collect()
        };
        let mut out = Physical::default();
        for &e in set {
            let v = get(e);
            match e {
                Effect::GroundEffect => out.ge = Some(v),
                Effect::MotorLag => out.tau = Some(tau),
                Effect::Drag => out.drag = Some(std::array::from_fn(|j| v[j])),
                Effect::Wind => {
                    let kr = get(Effect::Drag)[0];
                    out.wind = Some(if kr.abs() > 1e-3 {
                        [v[0] / kr, v[1] / kr]
                    } else {
                        [0.0, 0.0]
                    });
                }
                Effect::ThrustScale => out.thrust_scale = Some(v[0]),
                Effect::ThrustCurve => out.thrust_curve = Some(v[0]),
                Effect::BatterySag => out.battery = Some(v[0]),
                Effect::ComOffset => out.com = Some([v[0], v[1]]),
                Effect::ThrustAxis => out.thrust_axis = Some([v[0], v[1]]),
                Effect::InertiaError => out.inertia = Some(v[0]),
                Effect::MassError => out.mass = Some(v[0]),
            }
        }
        out
    }

    pub(crate) fn ge_config(&self) -> Option<GroundEffectConfig> {
        let ge = self.ge.as_ref()?;
        // The fitted surface sampled for the plant: at its height nodes
        // (exact: it is linear between them) and every `PLANT_TILT_STEP_DEG`
        // of tilt (bilinear between), the table from 0 deg.
        let tilts_deg: Vec<f64> = (0..=PLANT_TILT_ROWS)
            .map(|r| r as f64 * PLANT_TILT_STEP_DEG)
            .collect();
        let gain: Vec<Vec<f64>> = tilts_deg
            .iter()
            .map(|t| {
                GE_HEIGHTS
                    .iter()
                    .map(|h| effects::ge_gain(ge, *h, t.to_radians()).clamp(-0.9, 5.0))
                    .collect()
            })
            .collect();
        Some(GroundEffectConfig {
            enabled: true,
            // Unused: the table starts at 0 deg.
            rotor_radius: GroundEffectConfig::default().rotor_radius,
            classical_below_deg: 0.0,
            correlation_time: 0.05,
            heights: GE_HEIGHTS.to_vec(),
            std: vec![vec![0.0; GE_HEIGHTS.len()]; tilts_deg.len()],
            tilts_deg,
            gain,
        })
    }

    /// The plant's reading of [`Physical::toml`] (the ideal plant when it
    /// refuses the file).
    pub(crate) fn plant_config(
        &self,
        convention: ArmInertiaConvention,
    ) -> atmo_plant::config::PlantConfig {
        use atmo_core::ConfigFile as _;
        atmo_plant::config::PlantConfig::from_toml_str(&self.toml(convention, "fold"), "fold")
            .unwrap_or_else(|_| {
                let mut cfg = atmo_plant::config::PlantConfig::ideal();
                cfg.arm_inertia_convention = convention;
                cfg
            })
    }

    /// The plant file text.
    pub(crate) fn toml(&self, convention: ArmInertiaConvention, header: &str) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# Fitted by `atmo-sim explain`: {header}");
        let _ = writeln!(
            s,
            "# A plant file (config/plant.toml format): load it with PlantConfig::load.\n\
             # Effects are relative to the robot file the analysis was given; the arm\n\
             # inertia is read the way that robot file reads it."
        );
        let _ = writeln!(s, "dt = 0.001");
        let _ = writeln!(
            s,
            "arm_inertia_convention = \"{}\"",
            convention_name(convention)
        );
        let fmt = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:.6}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        if let Some(ge) = self.ge_config() {
            let _ = writeln!(s, "\n[effects.ground_effect]");
            let _ = writeln!(
                s,
                "# Thrust gain T/T_inf - 1 by rotor hub height (m) and tilt (deg): the fitted\n# surface sampled every 5 deg from 0 (no classical law: classical_below_deg = 0)."
            );
            let _ = writeln!(s, "rotor_radius = {:.6}", ge.rotor_radius);
            let _ = writeln!(s, "classical_below_deg = {:.1}", ge.classical_below_deg);
            let _ = writeln!(s, "correlation_time = {}", ge.correlation_time);
            let _ = writeln!(s, "heights = [{}]", fmt(&ge.heights));
            let _ = writeln!(s, "tilts_deg = [{}]", fmt(&ge.tilts_deg));
            let _ = writeln!(s, "gain = [");
            for row in &ge.gain {
                let _ = writeln!(s, "    [{}],", fmt(row));
            }
            let _ = writeln!(s, "]");
            let _ = writeln!(s, "std = [");
            for row in &ge.std {
                let _ = writeln!(s, "    [{}],", fmt(row));
            }
            let _ = writeln!(s, "]");
        }
        if let Some(tau) = self.tau {
            let _ = writeln!(
                s,
                "\n[effects.motor_lag]\ntime_constant = {:.6}\ncurve = 0.0",
                tau.clamp(1e-4, 1.0)
            );
        }
        if self.drag.is_some() || self.wind.is_some() {
            let d = self.drag.unwrap_or([0.0; DRAG_WIDTH]);
            let _ = writeln!(
                s,
                "\n[effects.drag]\nrotor_drag = {:.6}\naxial_drag = {:.6}\nbody_cd_area = [{}]\nair_density = {}",
                d[0].clamp(0.0, 100.0),
                d[1].clamp(0.0, 100.0),
                fmt(&[
                    d[2].clamp(0.0, 10.0),
                    d[3].clamp(0.0, 10.0),
                    d[4].clamp(0.0, 10.0)
                ]),
                effects::AIR_DENSITY
            );
        }
        if let Some(w) = self.wind {
            let _ = writeln!(
                s,
                "\n[effects.wind]\nsteady = [{}]\nturbulence_std = [0.0, 0.0, 0.0]",
                fmt(&[w[0].clamp(-50.0, 50.0), w[1].clamp(-50.0, 50.0), 0.0])
            );
        }
        if let Some(f) = self.thrust_curve {
            let _ = writeln!(
                s,
                "\n[effects.thrust_curve]\n# thrust (1 - curve) u + curve u^2 of full thrust\ncurve = {:.6}",
                f.clamp(-1.0, 1.0)
            );
        }
        if let Some(b) = self.battery {
            let sag = (b * 3600.0 * BATTERY_CAPACITY_WH / BATTERY_FULL_POWER_W).clamp(0.0, 0.9);
            let _ = writeln!(
                s,
                "\n[effects.battery_sag]\n# thrust x (1 - sag E / capacity), E the energy drawn\ncapacity_wh = {BATTERY_CAPACITY_WH}\nused_wh = 0.0\nfull_power_w = {BATTERY_FULL_POWER_W}\nsag = {sag:.6}"
            );
        }
        if let Some(c) = self.com {
            let _ = writeln!(
                s,
                "\n[effects.com_offset]\noffset = [{}]",
                fmt(&[c[0].clamp(-0.1, 0.1), c[1].clamp(-0.1, 0.1), 0.0])
            );
        }
        if let Some(t) = self.thrust_axis {
            let _ = writeln!(
                s,
                "\n[effects.thrust_axis]\ntilt = [{}]",
                fmt(&[t[0].clamp(-0.2, 0.2), t[1].clamp(-0.2, 0.2)])
            );
        }
        if self.thrust_scale.is_some() || self.mass.is_some() || self.inertia.is_some() {
            // A thrust scale (1 + s) acts on the rigid body exactly like mass,
            // first moment and inertia all divided by (1 + s).
            let s_t = 1.0 + self.thrust_scale.unwrap_or(0.0);
            let ms = (1.0 + self.mass.unwrap_or(0.0)) / s_t;
            let is = (1.0 + self.inertia.unwrap_or(0.0)) / s_t;
            let _ = writeln!(
                s,
                "\n[effects.mass_error]\n# mass_error {:.4}, inertia_error {:.4}, thrust_scale {:.4} (a thrust scale\n# 1 + s is written as mass and inertia scaled by 1 / (1 + s): the same dynamics)\nmass_scale = {:.6}\ninertia_scale = {:.6}",
                self.mass.unwrap_or(0.0),
                self.inertia.unwrap_or(0.0),
                self.thrust_scale.unwrap_or(0.0),
                ms.clamp(0.5, 2.0),
                is.clamp(0.5, 2.0)
            );
        }
        s
    }
}
