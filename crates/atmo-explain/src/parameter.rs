//! The finder's parameters as a type: each parameter a candidate effect
//! reports, with the name `explain.json` and the report give it, its
//! physical range (the table in docs/explain.md) and its unit, declared
//! once here. The acceptance's range test, the fit's coefficient bounds
//! and the report read them from [`Param`]; nothing looks a parameter up
//! by its name.

use std::borrow::Cow;
use std::fmt;

use serde::{Serialize, Serializer};

use crate::effects::{Effect, GE_WIDTH, ge_coefficient_name};
use crate::physical::{BATTERY_CAPACITY_WH, BATTERY_FULL_POWER_W};

/// A body axis of a parameter with one value per axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    /// The two in-plane axes.
    pub const XY: [Axis; 2] = [Axis::X, Axis::Y];
    /// The three body axes.
    pub const XYZ: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    /// `x`, `y` or `z`: the suffix of the parameter's name.
    pub fn suffix(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
        }
    }
}

/// A parameter of a candidate effect, as reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Param {
    /// Coefficient of the ground-effect gain `T/T_inf - 1` at height node
    /// `effects::GE_HEIGHTS[height]` and tilt spline `tilt`
    /// ([`crate::effects::ge_basis`]); the gains themselves are reported on
    /// a grid (`ground_effect_gain_grid`).
    Gain { height: usize, tilt: usize },
    /// The motor lag's time constant (profiled).
    TimeConstant,
    /// Scale of the lag term (1 = the lag as profiled).
    LagTermScale,
    /// Linear rotor drag in the disc plane.
    RotorDrag,
    /// Thrust lost to axial inflow.
    AxialDrag,
    /// Quadratic body drag `Cd A` along a body axis.
    BodyCdArea(Axis),
    /// Steady wind component (NED).
    SteadyWind(Axis),
    /// Thrust scale - 1.
    ThrustScaleMinusOne,
    /// Quadratic share f of the command-to-thrust curve.
    QuadraticShare,
    /// Thrust fraction lost over a battery's energy.
    Sag,
    /// Centre-of-mass offset in the body x-y plane.
    ComOffset(Axis),
    /// Thrust axis turned about a body axis.
    ThrustAxisTilt(Axis),
    /// Inertia scale - 1.
    InertiaScaleMinusOne,
    /// Mass scale - 1.
    MassScaleMinusOne,
}

impl Param {
    /// The effect the parameter belongs to.
    pub fn effect(self) -> Effect {
        match self {
            Param::Gain { .. } => Effect::GroundEffect,
            Param::TimeConstant | Param::LagTermScale => Effect::MotorLag,
            Param::RotorDrag | Param::AxialDrag | Param::BodyCdArea(_) => Effect::Drag,
            Param::SteadyWind(_) => Effect::Wind,
            Param::ThrustScaleMinusOne => Effect::ThrustScale,
            Param::QuadraticShare => Effect::ThrustCurve,
            Param::Sag => Effect::BatterySag,
            Param::ComOffset(_) => Effect::ComOffset,
            Param::ThrustAxisTilt(_) => Effect::ThrustAxis,
            Param::InertiaScaleMinusOne => Effect::InertiaError,
            Param::MassScaleMinusOne => Effect::MassError,
        }
    }

    /// The name in the report and `explain.json`.
    pub fn name(self) -> Cow<'static, str> {
        let axis = |stem: &str, a: Axis| Cow::Owned(format!("{stem}_{}", a.suffix()));
        match self {
            Param::Gain { height, tilt } => Cow::Owned(ge_coefficient_name(height, tilt)),
            Param::TimeConstant => "time_constant".into(),
            Param::LagTermScale => "lag_term_scale".into(),
            Param::RotorDrag => "rotor_drag".into(),
            Param::AxialDrag => "axial_drag".into(),
            Param::BodyCdArea(a) => axis("body_cd_area", a),
            Param::SteadyWind(a) => axis("steady", a),
            Param::ThrustScaleMinusOne => "scale_minus_one".into(),
            Param::QuadraticShare => "quadratic_share".into(),
            Param::Sag => "sag".into(),
            Param::ComOffset(a) => axis("offset", a),
            Param::ThrustAxisTilt(a) => axis("tilt", a),
            Param::InertiaScaleMinusOne => "inertia_scale_minus_one".into(),
            Param::MassScaleMinusOne => "mass_scale_minus_one".into(),
        }
    }

    /// `effect.parameter`, the name of a combined finding's parts.
    pub fn qualified(self) -> String {
        format!("{}.{}", self.effect(), self.name())
    }

    /// Its unit, as the report prints it.
    pub fn unit(self) -> Cow<'static, str> {
        match self {
            Param::Gain { .. }
            | Param::ThrustScaleMinusOne
            | Param::QuadraticShare
            | Param::InertiaScaleMinusOne
            | Param::MassScaleMinusOne => "1".into(),
            Param::BodyCdArea(_) => "m^2".into(),
            Param::TimeConstant => "s".into(),
            Param::LagTermScale => "1 (1 = consistent)".into(),
            Param::RotorDrag | Param::AxialDrag => "N/(m/s)".into(),
            Param::SteadyWind(_) => "m/s (NED)".into(),
            Param::Sag => Cow::Owned(format!(
                "thrust fraction at {BATTERY_CAPACITY_WH} Wh drawn at {BATTERY_FULL_POWER_W} W per rotor"
            )),
            Param::ComOffset(_) => "m".into(),
            Param::ThrustAxisTilt(_) => "rad".into(),
        }
    }

    /// Its physical range (docs/explain.md, "physical ranges"): a value
    /// beyond it is not a finding, one at a bound is not identified.
    pub fn range(self) -> (f64, f64) {
        match self {
            Param::Gain { .. } => (-0.5, 3.0),
            Param::TimeConstant => (0.005, 0.2),
            Param::LagTermScale => (0.5, 1.5),
            Param::RotorDrag | Param::AxialDrag => (0.0, 5.0),
            Param::BodyCdArea(_) => (0.0, 1.0),
            Param::SteadyWind(_) => (-15.0, 15.0),
            Param::ThrustScaleMinusOne | Param::MassScaleMinusOne => (-0.5, 0.5),
            Param::QuadraticShare => (-0.6, 0.6),
            Param::Sag => (0.0, 0.5),
            Param::ComOffset(_) => (-0.05, 0.05),
            Param::ThrustAxisTilt(_) => (-0.1, 0.1),
            Param::InertiaScaleMinusOne => (-0.5, 1.0),
        }
    }

    /// The parameter each linear coefficient of `e` is, in column order;
    /// `None` where the coefficient is not the parameter itself (the
    /// wind's `k_r w` products, the battery's loss per energy).
    pub fn of_coefficient(e: Effect, column: usize) -> Option<Param> {
        let axis = |j: usize| Axis::XYZ[j];
        match e {
            Effect::GroundEffect if column < GE_WIDTH => Some(Param::Gain {
                height: column % 4,
                tilt: column / 4,
            }),
            Effect::MotorLag => Some(Param::LagTermScale),
            Effect::Drag => Some(match column {
                0 => Param::RotorDrag,
                1 => Param::AxialDrag,
                j => Param::BodyCdArea(axis(j - 2)),
            }),
            Effect::ThrustAxis => Some(Param::ThrustAxisTilt(axis(column))),
            Effect::ThrustScale => Some(Param::ThrustScaleMinusOne),
            Effect::ThrustCurve => Some(Param::QuadraticShare),
            Effect::ComOffset => Some(Param::ComOffset(axis(column))),
            Effect::InertiaError => Some(Param::InertiaScaleMinusOne),
            Effect::MassError => Some(Param::MassScaleMinusOne),
            Effect::GroundEffect | Effect::Wind | Effect::BatterySag => None,
        }
    }

    /// The parameters the report gives for `e`, in order.
    pub fn of_effect(e: Effect) -> Vec<Param> {
        match e {
            Effect::MotorLag => vec![Param::TimeConstant, Param::LagTermScale],
            Effect::Wind => Axis::XY.map(Param::SteadyWind).to_vec(),
            Effect::BatterySag => vec![Param::Sag],
            _ => (0..e.width())
                .filter_map(|j| Param::of_coefficient(e, j))
                .collect(),
        }
    }
}

impl fmt::Display for Param {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

impl Serialize for Param {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.name())
    }
}

/// Serializes a parameter as [`Param::qualified`].
pub(crate) fn serialize_qualified<S: Serializer>(p: &Param, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&p.qualified())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_effect_reports_its_own_parameters_with_ranges_that_hold_zero_or_one() {
        for e in Effect::ALL {
            for p in Param::of_effect(e) {
                assert_eq!(p.effect(), e, "{p}");
                let (lo, hi) = p.range();
                assert!(lo < hi, "{p}");
                assert!(!p.unit().is_empty(), "{p}");
            }
        }
        // The coefficient names the fit prints are the parameters' names.
        let names = Effect::GroundEffect.coefficient_names();
        for (j, n) in names.iter().enumerate() {
            assert_eq!(
                Param::of_coefficient(Effect::GroundEffect, j)
                    .unwrap()
                    .name(),
                *n
            );
        }
        assert_eq!(Param::of_effect(Effect::Drag).len(), Effect::Drag.width());
        assert_eq!(
            Param::Gain { height: 0, tilt: 0 }.name(),
            "gain(h=0.25 m, spline peaking at -22.5 deg)"
        );
        assert_eq!(Param::SteadyWind(Axis::X).range(), (-15.0, 15.0));
    }

    #[test]
    fn a_parameter_serializes_as_its_name() {
        let json = serde_json::to_string(&Param::BodyCdArea(Axis::Z)).unwrap();
        assert_eq!(json, "\"body_cd_area_z\"");
        assert_eq!(
            Param::BodyCdArea(Axis::Z).qualified(),
            "drag.body_cd_area_z"
        );
        for e in Effect::ALL {
            assert_eq!(
                serde_json::to_string(&e).unwrap(),
                format!("\"{}\"", e.name())
            );
        }
    }
}
