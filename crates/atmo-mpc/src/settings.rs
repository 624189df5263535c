//! MPC settings: the `config/mpc.toml` layout, its loading and validation.
//!
//! Parsing is strict (unknown or missing keys are errors naming file, line and
//! key, via atmo-core's [`ConfigFile`]); every value is then range-checked.

use std::collections::BTreeMap;
use std::path::Path;

use atmo_core::config_file::ConfigFile;
use atmo_core::model::{Input, NU, NX, State};
use serde::Deserialize;

use crate::error::{MpcError, Result};

atmo_core::params! {
    /// The whole `config/mpc.toml` file.
    #[derive(Debug, Clone, PartialEq)]
    pub struct MpcFile {
        pub horizon: HorizonSettings;
        pub cost: CostSettings;
        /// Named cost presets (`fig5`, `default`).
        pub presets: BTreeMap<String, CostPreset>;
        pub solver: SolverSettings;
        pub feedback: FeedbackSettings;
        pub failure: FailureSettings;
        pub model: ModelSettings;
        /// The tilt as a decision of the MPC in the transition (absent: the
        /// paper's tilt law everywhere).
        pub tilt_plan: Option<TiltPlanSettings> = None;
    }
    check |_table, c, prefix| {
        if presets.is_empty() {
            return Err(c.fail(&atmo_core::params::key(prefix, "presets"), "at least one cost preset", "none"));
        }
        Ok(())
    }
}

atmo_core::params! {
    /// `[tilt_plan]`: the tilt-rate input and the landing objective (crate
    /// docs, docs/landing.md).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct TiltPlanSettings {
        /// Whether the flight stack lets the MPC plan the tilt in the transition.
        pub enabled: bool;
        /// Weight on `(varphi_k - varphi_max)^2` at every stage.
        pub tilt_weight: f64, range 0.0..=1e6, unit "1/rad^2";
        /// Weight on `(v_z,k - v_z,ref,k)^2` at every stage before the touchdown.
        pub descent_speed_weight: f64, range 0.0..=1e6, unit "s^2/m^2";
        /// Weight on the tilt rate `omega_k^2` (> 0: the QP stays strictly
        /// convex in the tilt rate).
        pub rate_weight: f64, range 1e-9..=1e6, unit "s^2/rad^2";
        /// Weight on `pitch_k^2 + roll_k^2` at every stage before the
        /// touchdown: the wheels touch together (the paper's blended cost
        /// weighs no attitude angle near the ground, where the ground
        /// effect's fluctuating thrust rolls the robot).
        pub level_weight: f64, range 0.0..=1e6, unit "1/rad^2";
        /// Weight on `(varphi - varphi_max)^2` at the predicted touchdown.
        pub touchdown_tilt_weight: f64, range 0.0..=1e6, unit "1/rad^2";
        /// Weight on `(v_z - touchdown_speed)^2` at the predicted touchdown.
        pub touchdown_speed_weight: f64, range 0.0..=1e6, unit "s^2/m^2";
        /// The vertical speed aimed at when the wheels touch (down positive).
        pub touchdown_speed: f64, range 0.0..=2.0, unit "m/s";
        /// Upper bound of every rotor command while the tilt is planned (the
        /// thrust margin kept for attitude control).
        pub thrust_max: f64, range 0.1..=1.0;
        /// Retired key `rotor_thrust_max` (a bound of each rotor above a bound
        /// of their mean, removed: docs/decisions/2026-12-05-landing-decision.md).
        /// Logs written before its removal carry it at `thrust_max`, which is
        /// what every rotor is bounded by now, so it is accepted at that value
        /// only and refused otherwise; never read.
        pub retired_rotor_thrust_max: Option<f64> = None, key "rotor_thrust_max";
    }
    check |_table, c, prefix| {
        if let Some(v) = retired_rotor_thrust_max {
            // Retired: only the value that reproduces today's bound.
            let key = atmo_core::params::key(prefix, "rotor_thrust_max (retired key: remove it)");
            c.range(&key, *v, *thrust_max..=*thrust_max, "")?;
        }
        Ok(())
    }
}

/// Which thrust-gain surface the prediction model carries near the ground.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GroundEffectSource {
    /// The nominal model: no ground effect.
    None,
    /// The plant's documented default surface (docs/ground_effect.md).
    PlantDefault,
    /// `[effects.ground_effect]` of a plant file, e.g. the
    /// `fitted_effects.toml` that `atmo-sim explain` writes.
    File(std::path::PathBuf),
}

impl<'de> Deserialize<'de> for GroundEffectSource {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        Ok(match text.as_str() {
            "none" => Self::None,
            "default" => Self::PlantDefault,
            path => Self::File(path.into()),
        })
    }
}

atmo_core::params! {
    /// `[model]`: what the prediction model carries besides the rigid body.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ModelSettings {
        /// `"none"`, `"default"` or the path of a plant file.
        pub ground_effect: GroundEffectSource;
    }
}

atmo_core::params! {
    /// `[horizon]`: the prediction horizon.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct HorizonSettings {
        /// Prediction horizon T.
        pub duration: f64, range 0.01..=10.0, unit "s";
        /// Number of shooting intervals N.
        pub steps: usize, range 1..=50, unit "intervals";
        /// Controller period, at most a stage (T / N): the plan is shifted
        /// by this much each tick.
        pub tick_period: f64, range 1e-4..=*duration / *steps as f64, unit "s";
    }
}

atmo_core::params! {
    /// `[cost]`: how the flight stack blends the preset's weights.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct CostSettings {
        /// Ticks between two recomputations of alpha by the flight stack.
        pub alpha_refresh_ticks: u32, range 1..=10_000, unit "ticks";
        /// `Q_N = terminal_scale * Q(alpha)`.
        pub terminal_scale: f64, range 0.0..=1e6;
    }
}

atmo_core::params! {
    /// One set of diagonal weights: `Q_1, Q_2` (12) and `R_1, R_2` (4),
    /// finite and >= 0; the input weights > 0, so that the QP stays
    /// strictly convex in the inputs whatever alpha is.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct CostPreset {
        /// State weight Q_1 (x, y, z, yaw, pitch, roll, velocities, rates).
        pub q1: [f64; NX];
        /// State weight Q_2, blended with Q_1 by alpha.
        pub q2: [f64; NX];
        /// Input weight R_1 (the four rotors).
        pub r1: [f64; NU];
        /// Input weight R_2, blended with R_1 by alpha.
        pub r2: [f64; NU];
    }
    check |_table, c, prefix| {
        let key = |name| atmo_core::params::key(prefix, name);
        for (name, values) in [("q1", &q1[..]), ("q2", &q2[..]), ("r1", &r1[..]), ("r2", &r2[..])] {
            if let Some(v) = values.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
                return Err(c.fail(&key(name), "finite weights >= 0", v));
            }
        }
        for (name, values) in [("r1", r1), ("r2", r2)] {
            if let Some(v) = values.iter().find(|v| **v <= 0.0) {
                return Err(c.fail(&key(name), "input weights > 0", v));
            }
        }
        Ok(())
    }
}

impl CostPreset {
    /// Blended diagonal state weight `alpha Q1 + (1 - alpha) Q2`.
    pub fn state_weight(&self, alpha: f64) -> State {
        State::from_fn(|i, _| alpha * self.q1[i] + (1.0 - alpha) * self.q2[i])
    }

    /// Blended diagonal input weight `alpha R1 + (1 - alpha) R2`.
    pub fn input_weight(&self, alpha: f64) -> Input {
        Input::from_fn(|i, _| alpha * self.r1[i] + (1.0 - alpha) * self.r2[i])
    }
}

/// Which QP the RTI step builds.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Formulation {
    /// States eliminated: 4N inputs, dense Hessian, box constraints only.
    Condensed,
    /// Multiple shooting: states and inputs, block-sparse equality constraints.
    Sparse,
}

atmo_core::params! {
    /// `[solver]`: the interior-point QP solver (Clarabel).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct SolverSettings {
        /// `condensed` or `sparse` (see [`Formulation`]).
        pub formulation: Formulation;
        /// Clarabel interior-point iteration cap.
        pub max_iter: u32, range 1..=1000, unit "iterations";
        /// Clarabel time limit per solve.
        pub time_limit: f64, range 1e-5..=10.0, unit "s";
        /// Clarabel's absolute duality-gap tolerance.
        pub tol_gap_abs: f64, range 1e-12..=1e-2;
        /// Clarabel's relative duality-gap tolerance.
        pub tol_gap_rel: f64, range 1e-12..=1e-2;
        /// Clarabel's feasibility tolerance.
        pub tol_feas: f64, range 1e-12..=1e-2;
        /// Clarabel's Ruiz equilibration (computed once, from the start-up QP).
        pub equilibrate: bool;
        /// Clarabel's iterative refinement of each KKT solve.
        pub iterative_refinement: bool;
        /// Fraction of the step to the boundary of the cone an interior-point
        /// iteration takes (Clarabel's default 0.99; 1 would leave the interior).
        pub max_step_fraction: f64, range 0.5..=0.9999;
    }
}

/// How the feedback phase turns the estimate into the QP's solution.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum FeedbackMethod {
    /// Clarabel solves at the predicted state in the preparation; the
    /// feedback walks the exact parametric active-set homotopy from there to
    /// the estimate (condensed formulation only; the sparse one uses Clarabel).
    Homotopy,
    /// A full Clarabel solve at the estimate in the feedback.
    Clarabel,
}

/// Where the preparation expects the next estimate.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Predictor {
    /// The shifted plan's first state (`dx_0 = 0`).
    Plan,
    /// One RK4 step of the model over a controller period from the last
    /// estimate with the command applied after it.
    Model,
}

atmo_core::params! {
    /// `[feedback]`: how the estimate enters the plan each tick.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct FeedbackSettings {
        /// `homotopy` or `clarabel` (see [`FeedbackMethod`]).
        pub method: FeedbackMethod;
        /// `plan` or `model` (see [`Predictor`]).
        pub predictor: Predictor;
        /// Working-set changes the feedback's homotopy may make before it falls
        /// back to a full Clarabel solve at the estimate.
        pub max_active_set_changes: u32, range 0..=10_000, unit "changes";
        /// The same cap for the preparation's walk from Clarabel's active set to
        /// the exact solution at the predicted state.
        pub max_preparation_changes: u32, range 0..=10_000, unit "changes";
    }
}

atmo_core::params! {
    /// `[failure]`: what a failed solve leaves the robot flying.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct FailureSettings {
        /// Ticks flown on the shifted previous plan before reporting Failed.
        pub grace_ticks: u32, range 0..=10_000, unit "ticks";
    }
}

/// Everything one controller needs: the file with one preset chosen.
#[derive(Debug, Clone, PartialEq)]
pub struct MpcSettings {
    pub horizon: HorizonSettings,
    pub cost: CostSettings,
    pub preset_name: String,
    pub weights: CostPreset,
    pub solver: SolverSettings,
    pub feedback: FeedbackSettings,
    pub failure: FailureSettings,
    pub model: ModelSettings,
    pub tilt_plan: Option<TiltPlanSettings>,
}

impl MpcSettings {
    /// Stage length `T / N`, s.
    pub fn stage_dt(&self) -> f64 {
        self.horizon.duration / self.horizon.steps as f64
    }

    /// The shipped `config/mpc.toml` with the named preset.
    pub fn atmo(preset: &str) -> Result<Self> {
        MpcFile::from_toml_str(include_str!("../../../config/mpc.toml"), "config/mpc.toml")?
            .settings(preset)
    }
}

impl ConfigFile for MpcFile {
    type Error = MpcError;

    fn validate(&self, file: &Path) -> Result<()> {
        Ok(atmo_core::params::check_file(self, file)?)
    }
}

impl MpcFile {
    /// The settings with preset `name` chosen.
    pub fn settings(&self, name: &str) -> Result<MpcSettings> {
        let weights = *self
            .presets
            .get(name)
            .ok_or_else(|| MpcError::UnknownPreset {
                name: name.to_string(),
                known: self.presets.keys().cloned().collect::<Vec<_>>().join(", "),
            })?;
        Ok(MpcSettings {
            horizon: self.horizon,
            cost: self.cost,
            preset_name: name.to_string(),
            weights,
            solver: self.solver,
            feedback: self.feedback,
            failure: self.failure,
            model: self.model.clone(),
            tilt_plan: self.tilt_plan,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SHIPPED: &str = include_str!("../../../config/mpc.toml");

    #[test]
    fn shipped_file_has_both_paper_presets() {
        let fig5 = MpcSettings::atmo("fig5").unwrap();
        assert_eq!(fig5.weights.q1[5], 20.0);
        assert_eq!(fig5.weights.q2[..9], [0.0; 9]);
        let other = MpcSettings::atmo("default").unwrap();
        assert_eq!(other.weights.q1[8], 0.8);
        assert_eq!(other.weights.q2[9..], [1.5, 2.7, 2.0]);
        assert_eq!(other.horizon.steps, 10);
        assert!((other.stage_dt() - 0.1).abs() < 1e-15);
        assert_eq!(other.cost.alpha_refresh_ticks, 10);
        assert_eq!(other.weights.r1, [0.1; 4]);
    }

    #[test]
    fn unknown_key_is_an_error_naming_it() {
        let text = SHIPPED.replace("steps = 10", "steps = 10\nstepz = 3");
        let err = MpcFile::from_toml_str(&text, "mpc.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("stepz"), "{err}");
        assert!(err.contains("mpc.toml"), "{err}");
    }

    #[test]
    fn out_of_range_values_are_rejected() {
        let zero_r = SHIPPED.replacen("r1 = [0.1, 0.1, 0.1, 0.1]", "r1 = [0.1, 0.0, 0.1, 0.1]", 1);
        let err = MpcFile::from_toml_str(&zero_r, "mpc.toml")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("presets.default.r1") || err.contains("presets.fig5.r1"),
            "{err}"
        );
        let bad_tick = SHIPPED.replace("tick_period = 0.006666666666666667", "tick_period = 0.5");
        let err = MpcFile::from_toml_str(&bad_tick, "mpc.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("horizon.tick_period"), "{err}");
        let bad_formulation =
            SHIPPED.replace("formulation = \"condensed\"", "formulation = \"dense\"");
        assert!(MpcFile::from_toml_str(&bad_formulation, "mpc.toml").is_err());
        // A full step to the cone boundary would leave the interior.
        let full_step = SHIPPED.replace("max_step_fraction = 0.999", "max_step_fraction = 1.0");
        let err = MpcFile::from_toml_str(&full_step, "mpc.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("solver.max_step_fraction"), "{err}");
        // The retired rotor bound: accepted at `thrust_max` (older logs
        // carry it there), refused at any other value.
        let with_retired = SHIPPED.replace(
            "thrust_max = 0.95 ",
            "rotor_thrust_max = 0.95\nthrust_max = 0.95 ",
        );
        assert!(with_retired.contains("rotor_thrust_max = 0.95"));
        MpcFile::from_toml_str(&with_retired, "mpc.toml").unwrap();
        let raised = with_retired.replace("rotor_thrust_max = 0.95", "rotor_thrust_max = 1.0");
        let err = MpcFile::from_toml_str(&raised, "mpc.toml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("tilt_plan.rotor_thrust_max"), "{err}");
    }

    #[test]
    fn unknown_preset_lists_the_known_ones() {
        let err = MpcSettings::atmo("fig6").unwrap_err().to_string();
        assert!(err.contains("fig5") && err.contains("default"), "{err}");
    }

    #[test]
    fn blend_is_linear_in_alpha() {
        let p = MpcSettings::atmo("fig5").unwrap().weights;
        assert_eq!(p.state_weight(1.0)[0], 1.0);
        assert_eq!(p.state_weight(0.0)[0], 0.0);
        assert!((p.state_weight(0.25)[5] - (0.25 * 20.0)).abs() < 1e-12);
        assert!((p.input_weight(0.3)[2] - 0.1).abs() < 1e-15);
    }
}
