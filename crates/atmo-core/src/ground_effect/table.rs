//! Ground effect of a tilted rotor: the thrust gain surface `T / T_inf - 1`
//! over rotor height above ground and tilt varphi.
//!
//! Three regions (docs/ground_effect.md gives every number and its source):
//!
//! - varphi <= `classical_below_deg` (30 deg): the classical rotor law of
//!   Cheeseman and Bennett (1955), `T / T_inf = 1 / (1 - (R_p / (4 z))^2)`,
//!   with the distance along the (tilted) slipstream `z = h / cos varphi` and
//!   z held at or above `R_p / 2`, where the law stops being valid.
//! - varphi in [40, 70] deg: a table read from the description of the
//!   paper's load-cell results (Fig. 3C), bilinear in (h, varphi). Outside
//!   the measured heights the value is held (below 0.25 m) or the table's
//!   last column is used (above 0.72 m, where it is zero). Above 70 deg the
//!   70 deg row is held.
//! - between 30 and 40 deg: a linear blend from the classical law to the
//!   40 deg row, so the surface is continuous.
//!
//! Each entry has a mean and a standard deviation: near the ground at large
//! tilts the measured thrust fluctuates strongly. The plant draws the
//! fluctuation as a unit-variance first-order Gauss-Markov process per rotor
//! (correlation time `correlation_time`), so the thrust of rotor i is
//! `kT u_i (1 + mean(h_i, varphi) + std(h_i, varphi) n_i(t))`.

// What the plant's step calls here is `inline(always)`: atmo-plant compiles
// its step twice, portable and AVX2, and only code inlined into it gets the
// AVX2 copy (atmo-plant's `plant::step` and its `avx2_rule` test).
#![allow(clippy::inline_always)]

use std::path::Path;

use super::{GainPartials, ThrustGainSurface};
use crate::config_file::Checker;
use serde::Deserialize;

use crate::Result;

/// Heights of the default table (m of rotor hub above the ground plane).
pub const DEFAULT_HEIGHTS: [f64; 6] = [0.25, 0.35, 0.45, 0.55, 0.65, 0.72];
/// Tilts of the default table (deg).
pub const DEFAULT_TILTS_DEG: [f64; 4] = [40.0, 50.0, 60.0, 70.0];
/// Mean gain `T / T_inf - 1`, one row per tilt of [`DEFAULT_TILTS_DEG`].
pub const DEFAULT_GAIN: [[f64; 6]; 4] = [
    [0.090, 0.060, 0.035, 0.015, 0.005, 0.0], // 40 deg: clearly positive
    [0.190, 0.120, 0.070, 0.035, 0.010, 0.0], // 50 deg: largest, almost +20 %
    [0.070, 0.045, 0.025, 0.010, 0.003, 0.0], // 60 deg: clearly positive
    [-0.070, -0.045, -0.025, -0.010, -0.003, 0.0], // 70 deg: suction
];
/// Standard deviation of the gain, same layout as [`DEFAULT_GAIN`].
pub const DEFAULT_STD: [[f64; 6]; 4] = [
    [0.010, 0.008, 0.005, 0.003, 0.002, 0.0],
    [0.015, 0.010, 0.007, 0.004, 0.002, 0.0],
    [0.025, 0.018, 0.010, 0.005, 0.003, 0.0],
    [0.080, 0.055, 0.030, 0.015, 0.005, 0.0], // mean - std = -15 % at 0.25 m
];

crate::params! {
    /// `[effects.ground_effect]`: the thrust-gain surface near the ground.
    /// A file without a key takes the documented default surface's value
    /// (docs/ground_effect.md).
    #[derive(Debug, Clone, PartialEq)]
    pub struct GroundEffectConfig: Default {
        /// Whether the plant flies through (and the MPC predicts with) it.
        pub enabled: bool = true;
        /// Propeller radius R_p of the classical law.
        pub rotor_radius: f64 = 0.11, range 0.01..=1.0, unit "m";
        /// At and below this tilt only the classical law applies; between
        /// it and the first table tilt the two are blended linearly (at
        /// most the first table tilt; from that tilt on the table alone
        /// applies, so a table from 0 deg has no classical law).
        pub classical_below_deg: f64 = 30.0, unit "deg";
        /// Correlation time of the thrust fluctuation.
        pub correlation_time: f64 = 0.05, range 1e-4..=100.0, unit "s";
        /// Rotor hub heights of the table columns, increasing (two or more).
        pub heights: Vec<f64> = DEFAULT_HEIGHTS.to_vec(), range 0.0..=10.0, unit "m";
        /// Tilts of the table rows, increasing (two or more).
        pub tilts_deg: Vec<f64> = DEFAULT_TILTS_DEG.to_vec(), range 0.0..=90.0, unit "deg";
        /// Mean `T / T_inf - 1`, rows by tilt, columns by height (each in
        /// [-0.99, 10]).
        pub gain: Vec<Vec<f64>> = DEFAULT_GAIN.iter().map(|r| r.to_vec()).collect();
        /// Standard deviation of `T / T_inf - 1`, same layout (each in
        /// [0, 10]).
        pub std: Vec<Vec<f64>> = DEFAULT_STD.iter().map(|r| r.to_vec()).collect();
    }
    check |surface, c, prefix| surface.check_table(c, prefix)
}

/// A plant file's `[effects.ground_effect]` and nothing else of it: the
/// controller reads a plant file (`config/plant.toml`, a `fitted_effects.toml`)
/// for its surface only, so the other sections are the plant's to check.
#[derive(Deserialize)]
struct PlantFileEffects {
    #[serde(default)]
    effects: EffectsGroundEffect,
}

#[derive(Deserialize, Default)]
struct EffectsGroundEffect {
    ground_effect: Option<GroundEffectConfig>,
}

impl GroundEffectConfig {
    /// The same surface with the table's mean gains scaled by `scale` (the
    /// classical law below 30 deg and the spreads unchanged) and the tilt
    /// axis shifted by `shift_deg` (the table read at `varphi - shift`): a
    /// plant that differs from the controller's surface (the Monte Carlo).
    #[must_use]
    pub fn perturbed(&self, scale: f64, shift_deg: f64) -> Self {
        let mut out = self.clone();
        for row in &mut out.gain {
            for g in row.iter_mut() {
                *g *= scale;
            }
        }
        for t in &mut out.tilts_deg {
            *t += shift_deg;
        }
        out.classical_below_deg += shift_deg;
        out
    }

    /// The enabled `[effects.ground_effect]` of a plant file's `text` (read
    /// from `file`, named in errors), checked; `None` if it has none or it
    /// is disabled.
    ///
    /// # Errors
    /// Bad TOML, an unknown or mistyped key of the section (with line and
    /// key), a value out of range.
    pub fn from_plant_file(text: &str, file: &Path) -> Result<Option<Self>> {
        let parsed: PlantFileEffects = crate::config_file::parse_toml(text, file)?;
        let Some(config) = parsed.effects.ground_effect.filter(|g| g.enabled) else {
            return Ok(None);
        };
        config.validate(&Checker::new(file), "effects.ground_effect")?;
        Ok(Some(config))
    }

    /// Checks the table's shape and values; `prefix` is the key of the section.
    ///
    /// # Errors
    /// The first value out of range, naming its key.
    pub fn validate(&self, c: &Checker<'_>, prefix: &str) -> Result<()> {
        crate::params::Params::check(self, c, prefix)
    }

    /// What the ranges cannot say: the axes increase, the blend ends at
    /// the first table tilt, the tables have one row per tilt and one
    /// entry per height.
    fn check_table(&self, c: &Checker<'_>, prefix: &str) -> Result<()> {
        let key = |name: &str| crate::params::key(prefix, name);
        increasing(c, &key("heights"), &self.heights)?;
        increasing(c, &key("tilts_deg"), &self.tilts_deg)?;
        c.within(
            &key("classical_below_deg"),
            self.classical_below_deg,
            0.0,
            self.tilts_deg[0],
        )?;
        for (name, table, min) in [("gain", &self.gain, -0.99), ("std", &self.std, 0.0)] {
            if table.len() != self.tilts_deg.len() {
                return Err(c.fail(
                    &key(name),
                    format!("{} rows (one per tilt)", self.tilts_deg.len()),
                    table.len(),
                ));
            }
            for (r, row) in table.iter().enumerate() {
                let key = format!("{}[{r}]", key(name));
                if row.len() != self.heights.len() {
                    return Err(c.fail(
                        &key,
                        format!("{} entries (one per height)", self.heights.len()),
                        row.len(),
                    ));
                }
                for v in row {
                    c.within(&key, *v, min, 10.0)?;
                }
            }
        }
        Ok(())
    }
}

fn increasing(c: &Checker<'_>, key: &str, values: &[f64]) -> Result<()> {
    if values.len() < 2 {
        return Err(c.fail(key, "at least two values", values.len()));
    }
    if values.windows(2).any(|w| w[1] <= w[0]) {
        return Err(c.fail(key, "strictly increasing values", format!("{values:?}")));
    }
    Ok(())
}

/// The ground-effect surface, ready to evaluate (no allocation per call).
#[derive(Debug, Clone, PartialEq)]
pub struct GroundEffect {
    rotor_radius: f64,
    classical_below: f64,
    table_from: f64,
    pub correlation_time: f64,
    heights: Vec<f64>,
    tilts: Vec<f64>,
    gain: Vec<Vec<f64>>,
    std: Vec<Vec<f64>>,
}

/// A tilt's share of the surface (see [`GroundEffect::slice`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltSlice {
    inv_cos: f64,
    row: usize,
    row_weight: f64,
    /// 1 = classical law only, 0 = table only.
    classical_weight: f64,
}

/// Mean and standard deviation of `T / T_inf - 1` at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gain {
    pub mean: f64,
    pub std: f64,
}

// AVX2 rule: from here to the end of the file, step code (see plant::step):
// every function says `#[inline(always)]` or `#[inline(never)]`.

/// Cheeseman-Bennett: `T / T_inf - 1` for a rotor of radius `r` at distance
/// `z` from the ground, with z held at or above `r / 2`:
/// `1 / (1 - (r / 4z)^2) - 1 = r^2 / (16 z^2 - r^2)`, the second form with one
/// division instead of two dependent ones (it runs 16 times per plant step).
#[inline(always)]
pub fn cheeseman_bennett(r: f64, z: f64) -> f64 {
    let z = z.max(0.5 * r);
    let r2 = r * r;
    r2 / (16.0 * z * z - r2)
}

/// Index i with `xs[i] <= x <= xs[i + 1]` and the weight of `xs[i + 1]`,
/// with x clamped into the range.
#[inline(always)]
pub fn bracket(xs: &[f64], x: f64) -> (usize, f64) {
    let n = xs.len();
    if x <= xs[0] {
        return (0, 0.0);
    }
    if x >= xs[n - 1] {
        return (n - 2, 1.0);
    }
    let mut i = 0;
    while xs[i + 1] < x {
        i += 1;
    }
    (i, (x - xs[i]) / (xs[i + 1] - xs[i]))
}

impl GroundEffect {
    /// Builds the surface from a validated config.
    #[inline(never)] // start-up
    pub fn new(config: &GroundEffectConfig) -> Self {
        Self {
            rotor_radius: config.rotor_radius,
            classical_below: config.classical_below_deg.to_radians(),
            table_from: config.tilts_deg[0].to_radians(),
            correlation_time: config.correlation_time,
            heights: config.heights.clone(),
            tilts: config.tilts_deg.iter().map(|d| d.to_radians()).collect(),
            gain: config.gain.clone(),
            std: config.std.clone(),
        }
    }

    /// Everything about tilt `varphi` (rad) that the surface needs, computed
    /// once per tilt so that evaluating over heights costs no trigonometry.
    #[inline(always)]
    pub fn slice(&self, varphi: f64) -> TiltSlice {
        let (row, row_weight) = bracket(&self.tilts, varphi);
        // The table from its first tilt on (so a table from 0 deg leaves no
        // classical law), the classical law up to `classical_below`.
        let classical_weight = if varphi >= self.table_from {
            0.0
        } else if varphi <= self.classical_below {
            1.0
        } else {
            1.0 - (varphi - self.classical_below) / (self.table_from - self.classical_below)
        };
        TiltSlice {
            inv_cos: 1.0 / varphi.cos().max(0.05),
            row,
            row_weight,
            classical_weight,
        }
    }

    /// Bilinear table value at hub height `h` (m) in a tilt slice.
    #[inline(always)]
    fn table(&self, h: f64, s: &TiltSlice) -> Gain {
        let (i, wt) = (s.row, s.row_weight);
        let (j, wh) = bracket(&self.heights, h);
        let lerp2 = |t: &Vec<Vec<f64>>| {
            let a = t[i][j] * (1.0 - wh) + t[i][j + 1] * wh;
            let b = t[i + 1][j] * (1.0 - wh) + t[i + 1][j + 1] * wh;
            a * (1.0 - wt) + b * wt
        };
        Gain {
            mean: lerp2(&self.gain),
            std: lerp2(&self.std),
        }
    }

    /// `T / T_inf - 1` (mean and standard deviation) at hub height `h` (m)
    /// in a tilt slice.
    #[inline(always)]
    pub fn gain_in(&self, s: &TiltSlice, h: f64) -> Gain {
        let w = s.classical_weight;
        if w >= 1.0 {
            return Gain {
                mean: cheeseman_bennett(self.rotor_radius, h * s.inv_cos),
                std: 0.0,
            };
        }
        let table = self.table(h, s);
        if w <= 0.0 {
            return table;
        }
        Gain {
            mean: w * cheeseman_bennett(self.rotor_radius, h * s.inv_cos) + (1.0 - w) * table.mean,
            std: (1.0 - w) * table.std,
        }
    }

    /// `T / T_inf - 1` (mean and standard deviation) for a rotor whose hub
    /// is `h` m above the ground at tilt `varphi` rad.
    #[inline(never)] // not step code (tests, figures)
    pub fn gain(&self, h: f64, varphi: f64) -> Gain {
        self.gain_in(&self.slice(varphi), h)
    }

    /// The gain applied to a rotor: mean plus `n` standard deviations.
    #[inline(always)]
    pub fn sample(&self, s: &TiltSlice, h: f64, n: f64) -> f64 {
        let g = self.gain_in(s, h);
        // Thrust never reverses, however far the noise reaches.
        (g.mean + g.std * n).max(-0.9)
    }

    /// Validated config helper for tests and docs: the surface at the default table.
    #[inline(never)] // start-up
    pub fn default_surface() -> Self {
        Self::new(&GroundEffectConfig::default())
    }

    /// Checks a config against `file` (for callers outside a plant file).
    #[inline(never)] // start-up
    pub fn from_config(config: &GroundEffectConfig, file: &Path) -> Result<Self> {
        config.validate(&Checker::new(file), "effects.ground_effect")?;
        Ok(Self::new(config))
    }
}

/// `(i, w, slope)`: [`bracket`] and `dw/dx` (zero where x is clamped).
#[inline(never)] // not step code (the controller's model)
fn bracket_with_slope(xs: &[f64], x: f64) -> (usize, f64, f64) {
    let (i, w) = bracket(xs, x);
    let inside = x > xs[0] && x < xs[xs.len() - 1];
    let slope = if inside {
        1.0 / (xs[i + 1] - xs[i])
    } else {
        0.0
    };
    (i, w, slope)
}

/// `cheeseman_bennett(r, z)` and its derivative in z (zero where z is held).
#[inline(never)] // not step code
fn cheeseman_bennett_with_slope(r: f64, z: f64) -> (f64, f64) {
    let r2 = r * r;
    if z <= 0.5 * r {
        return (cheeseman_bennett(r, z), 0.0);
    }
    let den = 16.0 * z * z - r2;
    (r2 / den, -32.0 * z * r2 / (den * den))
}

impl GroundEffect {
    /// The mean gain and its exact partials in h and varphi (of the piece
    /// of the surface that holds the point): what the controller's model
    /// linearizes. The same value as [`GroundEffect::gain`]'s mean.
    #[inline(never)] // not step code
    pub fn mean_with_partials(&self, h: f64, varphi: f64) -> GainPartials {
        let cos = varphi.cos();
        let (inv_cos, d_inv_cos) = if cos > 0.05 {
            (1.0 / cos, varphi.sin() / (cos * cos))
        } else {
            (1.0 / 0.05, 0.0)
        };
        let (cb, cb_z) = cheeseman_bennett_with_slope(self.rotor_radius, h * inv_cos);
        let classical = GainPartials {
            gain: cb,
            d_height: cb_z * inv_cos,
            d_tilt: cb_z * h * d_inv_cos,
        };
        let (w, dw) = if varphi >= self.table_from {
            (0.0, 0.0)
        } else if varphi <= self.classical_below {
            (1.0, 0.0)
        } else {
            let span = self.table_from - self.classical_below;
            (1.0 - (varphi - self.classical_below) / span, -1.0 / span)
        };
        if w >= 1.0 {
            return classical;
        }
        let (i, wt, dwt) = bracket_with_slope(&self.tilts, varphi);
        let (j, wh, dwh) = bracket_with_slope(&self.heights, h);
        let t = &self.gain;
        let a = t[i][j] * (1.0 - wh) + t[i][j + 1] * wh;
        let b = t[i + 1][j] * (1.0 - wh) + t[i + 1][j + 1] * wh;
        let da_dh = (t[i][j + 1] - t[i][j]) * dwh;
        let db_dh = (t[i + 1][j + 1] - t[i + 1][j]) * dwh;
        let table = GainPartials {
            gain: a * (1.0 - wt) + b * wt,
            d_height: da_dh * (1.0 - wt) + db_dh * wt,
            d_tilt: (b - a) * dwt,
        };
        GainPartials {
            gain: w * classical.gain + (1.0 - w) * table.gain,
            d_height: w * classical.d_height + (1.0 - w) * table.d_height,
            d_tilt: w * classical.d_tilt
                + (1.0 - w) * table.d_tilt
                + dw * (classical.gain - table.gain),
        }
    }
}

impl ThrustGainSurface for GroundEffect {
    #[inline(never)] // not step code
    fn gain_partials(&self, height: f64, varphi: f64) -> GainPartials {
        self.mean_with_partials(height, varphi)
    }
}
