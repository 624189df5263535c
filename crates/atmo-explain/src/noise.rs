//! The noise floor from the velocity residual's structure function.
//!
//! `e_k` = recorded velocity (world) and body rates minus the nominal
//! model integrated along the run (the same trapezoid as [`crate::data`]).
//! Its structure function `D(L) = E[(e_{k+L} - e_k)^2]` over lags from one
//! sample to [`MAX_LAG_S`] (log-spaced) is modelled as
//!
//! `D(L) = 2 s_w^2 + 2 s_g^2 (1 - exp(-L h / tau)) + q L h + c (L h)^2`:
//!
//! white noise `s_w`, Gauss-Markov noise `s_g` with correlation time `tau`
//! (motion-capture velocities are often filtered: white alone misses it;
//! it saturates within the lags), a random walk `q` (an acceleration error
//! that changes faster than the lags: process noise, or a model error
//! driven by a command dither) and the quadratic growth of a slow model
//! error (an acceleration error `a` adds `a^2 (L h)^2`). Only the sensor
//! part (`s_w`, `s_g`) is the floor: `q` and `c` are what a model can
//! explain, never counted as noise.
//! Robust: `D(L)` is the median of the squared differences over
//! `0.4549` (the median of chi-square with one degree of freedom), so
//! tracking glitches do not set the floor. The floor is the noise part's
//! variance through the derivative taps:
//! `sum_ij g_i g_j R(|i - j|)`, `R(0) = s_w^2 + s_g^2`,
//! `R(m) = s_g^2 exp(-m h / tau)`.

/// Longest lag of the structure function (s).
pub const MAX_LAG_S: f64 = 0.5;

/// Correlation times tried for the Gauss-Markov part (s): up to half the
/// longest lag, so that it saturates within the lags (slower "noise" is
/// indistinguishable from a model error and is left to the model).
fn taus(dt: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut tau = 2.0 * dt;
    while tau <= 0.5 * MAX_LAG_S {
        out.push(tau);
        tau *= 1.4;
    }
    out
}

/// Log-spaced lags (samples) from 1 to `max_lag`.
fn lags(max_lag: usize) -> Vec<usize> {
    let mut out: Vec<usize> = Vec::new();
    let mut x = 1.0_f64;
    while (x.round() as usize) <= max_lag {
        let l = x.round() as usize;
        if out.last() != Some(&l) {
            out.push(l);
        }
        x *= 1.3;
    }
    out
}

/// Median of chi-square with one degree of freedom.
const CHI2_1_MEDIAN: f64 = 0.4549;

/// Robust structure function of each channel at the `lags` (linear
/// channels pooled over x, y, z).
fn structure(runs: &[Vec<[f64; 6]>], lags: &[usize]) -> Vec<[f64; 6]> {
    let mut out = vec![[0.0; 6]; lags.len()];
    let mut buf: Vec<f64> = Vec::new();
    for (row, &lag) in out.iter_mut().zip(lags) {
        for c in 0..6 {
            buf.clear();
            for run in runs {
                for k in lag..run.len() {
                    let d = run[k][c] - run[k - lag][c];
                    buf.push(d * d);
                }
            }
            if buf.is_empty() {
                continue;
            }
            let mid = buf.len() / 2;
            let (_, med, _) = buf.select_nth_unstable_by(mid, f64::total_cmp);
            row[c] = *med / CHI2_1_MEDIAN;
        }
        let lin = (row[0] + row[1] + row[2]) / 3.0;
        row[..3].fill(lin);
    }
    out
}

/// Bases of the structure-function model: constant, Gauss-Markov, random
/// walk, quadratic.
const BASES: usize = 4;

/// Non-negative least squares of `d ~ sum_j x_j basis_j` (relative errors)
/// over every subset of the bases; returns the coefficients and the
/// squared error.
fn fit_nonnegative(d: &[f64], basis: &[[f64; BASES]]) -> ([f64; BASES], f64) {
    let mut best = ([0.0; BASES], f64::INFINITY);
    for mask in 1u8..(1 << BASES) {
        let on: Vec<usize> = (0..BASES).filter(|j| mask & (1 << j) != 0).collect();
        let m = on.len();
        let mut ata = nalgebra::DMatrix::<f64>::zeros(m, m);
        let mut atb = nalgebra::DVector::<f64>::zeros(m);
        for (l, b) in basis.iter().enumerate() {
            let w = 1.0 / d[l].max(1e-30);
            for (i, &ji) in on.iter().enumerate() {
                atb[i] += b[ji] * w * d[l] * w;
                for (k, &jk) in on.iter().enumerate() {
                    ata[(i, k)] += b[ji] * w * b[jk] * w;
                }
            }
        }
        let Some(x) = ata.cholesky().map(|c| c.solve(&atb)) else {
            continue;
        };
        if x.iter().any(|v| *v < 0.0) {
            continue;
        }
        let mut coef = [0.0; BASES];
        for (i, &j) in on.iter().enumerate() {
            coef[j] = x[i];
        }
        let err: f64 = basis
            .iter()
            .enumerate()
            .map(|(l, b)| {
                let p: f64 = (0..BASES).map(|j| coef[j] * b[j]).sum();
                ((p - d[l]) / d[l].max(1e-30)).powi(2)
            })
            .sum();
        if err < best.1 {
            best = (coef, err);
        }
    }
    best
}

/// Standard deviation of the noise through the derivative `taps` (per
/// second) for each channel, from the velocity residual `runs` (one series
/// per run, at spacing `dt`).
pub fn floor_from_velocity_residual(runs: &[Vec<[f64; 6]>], taps: &[f64], dt: f64) -> [f64; 6] {
    let longest = runs.iter().map(Vec::len).max().unwrap_or(0) / 2;
    let max_lag = ((MAX_LAG_S / dt).round() as usize).min(longest).max(3);
    let lags = lags(max_lag);
    let d = structure(runs, &lags);
    let mut floor = [0.0; 6];
    for c in 0..6 {
        let dc: Vec<f64> = d.iter().map(|r| r[c]).collect();
        if dc.iter().all(|v| *v <= 0.0) {
            continue;
        }
        let mut best = (0.0, 0.0, 0.0, f64::INFINITY);
        for tau in taus(dt) {
            let basis: Vec<[f64; BASES]> = lags
                .iter()
                .map(|&l| {
                    let s = l as f64 * dt;
                    [1.0, 1.0 - (-s / tau).exp(), s, s * s]
                })
                .collect();
            let (x, err) = fit_nonnegative(&dc, &basis);
            if err < best.3 {
                best = (x[0] / 2.0, x[1] / 2.0, tau, err);
            }
        }
        let (white, gm, tau, _) = best;
        let r = |m: usize| {
            let gm_part = if tau > 0.0 {
                gm * (-(m as f64) * dt / tau).exp()
            } else {
                0.0
            };
            if m == 0 { white + gm_part } else { gm_part }
        };
        let mut var = 0.0;
        for (i, gi) in taps.iter().enumerate() {
            for (j, gj) in taps.iter().enumerate() {
                var += gi * gj * r(i.abs_diff(j));
            }
        }
        floor[c] = var.max(0.0).sqrt();
    }
    floor
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // reason: test code
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// White plus Gauss-Markov noise on top of a model error that grows
    /// the velocity residual quadratically: the floor is the noise's
    /// filtered level (simulated through the same taps), not the error's.
    #[test]
    fn floor_matches_filtered_coloured_noise_and_ignores_model_error() {
        let dt = 1.0 / 150.0;
        let half = crate::data::half_window(dt);
        let taps = crate::data::sg_derivative_taps(half, dt);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut gauss = || {
            let (a, b): (f64, f64) = (rng.random(), rng.random());
            (-2.0 * a.max(1e-300).ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let n = 20_000;
        let (sw, sg, tau) = (0.006, 0.004, 0.1);
        let phi = (-dt / tau).exp();
        let mut g = 0.0;
        let mut noise = Vec::with_capacity(n);
        for _ in 0..n {
            g = phi * g + sg * (1.0 - phi * phi).sqrt() * gauss();
            noise.push(sw * gauss() + g);
        }
        let filtered: Vec<f64> = (half..n - half)
            .map(|k| (0..taps.len()).map(|j| taps[j] * noise[k + j - half]).sum())
            .collect();
        let truth = (filtered.iter().map(|v| v * v).sum::<f64>() / filtered.len() as f64).sqrt();
        // Noise alone, then with a slow model error of about the floor's
        // size (0.05 m/s^2 sine over 3 s, in velocity).
        for (amplitude, tolerance) in [(0.0, 0.1), (0.05, 0.2)] {
            let run: Vec<[f64; 6]> = (0..n)
                .map(|k| {
                    let w = std::f64::consts::TAU / 3.0;
                    let v = noise[k] + amplitude / w * (w * k as f64 * dt).sin();
                    [v; 6]
                })
                .collect();
            let floor = floor_from_velocity_residual(&[run], &taps, dt);
            assert!(
                (floor[3] / truth - 1.0).abs() < tolerance,
                "model error {amplitude}: floor {} vs filtered noise {truth}",
                floor[3]
            );
        }
    }
}
