//! Where the residual lives: channels x envelope regions, each bin tested
//! against the noise floor.
//!
//! For every channel and every bin of an envelope variable (hub height
//! above ground, tilt, speed, thrust, time since start, command rate) and
//! every cell of the (height, tilt) map: the mean residual and its
//! mean square. Their standard errors come from batch means over 0.5 s
//! stretches (the filtered residual is correlated from sample to sample).
//! A bin carries residual beyond the noise floor when its mean is
//! significantly non-zero (bias) or its mean square significantly above the
//! floor's (excess), at a family-wise level of 0.1 % (Bonferroni over all
//! tests), and the excess is large enough to matter: |mean| > 0.3 floor or
//! RMS > 1.3 floor.

use serde::Serialize;

use crate::data::{CHANNELS, Envelope, Prepared};

/// Family-wise false-alarm probability of the locate tests.
pub const ALPHA: f64 = 1e-3;
/// Batch length for the standard errors (s).
pub const BATCH: f64 = 0.5;

/// Envelope variables.
pub const VARIABLES: [&str; 6] = [
    "height",
    "varphi",
    "speed",
    "thrust",
    "time",
    "command_rate",
];
/// Height bin edges of the heat map (m of mean hub height).
pub const HEIGHT_EDGES: [f64; 9] = [-1.0, 0.25, 0.35, 0.45, 0.6, 0.8, 1.2, 2.0, 1e9];
/// Tilt bin edges of the heat map (deg).
pub const VARPHI_EDGES: [f64; 7] = [-1.0, 15.0, 35.0, 45.0, 55.0, 65.0, 91.0];

fn value(e: &Envelope, var: usize) -> f64 {
    match var {
        0 => e.height,
        1 => e.varphi.to_degrees(),
        2 => e.speed,
        3 => e.thrust,
        4 => e.time,
        _ => e.command_rate,
    }
}

/// Statistics of one channel in one bin.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct CellStat {
    pub samples: usize,
    pub mean: f64,
    pub rms: f64,
    /// RMS over the channel's noise floor.
    pub rms_ratio: f64,
    pub z_bias: f64,
    pub z_excess: f64,
    /// Two-sided p-value of the stronger of the two tests.
    pub p_value: f64,
    pub flagged: bool,
}

/// A located discrepancy.
#[derive(Debug, Clone, Serialize)]
pub struct Located {
    pub channel: String,
    pub variable: String,
    /// Range of the variable (units: m, deg, m/s, command, s, 1/s).
    pub from: f64,
    pub to: f64,
    pub region: String,
    pub samples: usize,
    pub mean: f64,
    pub rms: f64,
    pub rms_ratio: f64,
    pub p_value: f64,
}

/// The result of locating.
#[derive(Debug, Clone, Serialize)]
pub struct Location {
    pub located: Vec<Located>,
    /// Heat map `[height bin][varphi bin][channel]`.
    pub heat: Vec<Vec<[CellStat; 6]>>,
    /// Per variable: bin edges and `[bin][channel]` statistics.
    pub bins: Vec<(String, Vec<f64>, Vec<[CellStat; 6]>)>,
    /// Channels with any flagged bin.
    pub channels: Vec<usize>,
    pub z_critical: f64,
}

/// Standard normal upper tail.
pub fn normal_sf(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Complementary error function (Numerical Recipes' erfcc, |err| < 1.2e-7).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.26551223
            + t * (1.00002368
                + t * (0.37409196
                    + t * (0.09678418
                        + t * (-0.18628806
                            + t * (0.27886807
                                + t * (-1.13520398
                                    + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277)))))))))
            .exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// z with `normal_sf(z) = p`.
pub fn normal_isf(p: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 40.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if normal_sf(mid) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

struct Acc {
    n: usize,
    sum: f64,
    sq: f64,
    batches: Vec<(usize, f64, f64)>,
    last_batch: i64,
}

impl Acc {
    fn new() -> Self {
        Self {
            n: 0,
            sum: 0.0,
            sq: 0.0,
            batches: Vec::new(),
            last_batch: -1,
        }
    }
    fn push(&mut self, batch: i64, r: f64) {
        self.n += 1;
        self.sum += r;
        self.sq += r * r;
        if batch != self.last_batch {
            self.batches.push((0, 0.0, 0.0));
            self.last_batch = batch;
        }
        let b = self.batches.last_mut().expect("pushed");
        b.0 += 1;
        b.1 += r;
        b.2 += r * r;
    }
    fn stat(&self, floor: f64, z_crit: f64) -> CellStat {
        if self.n == 0 {
            return CellStat::default();
        }
        let n = self.n as f64;
        let mean = self.sum / n;
        let ms = self.sq / n;
        let rms = ms.sqrt();
        let nb = self.batches.len();
        let mut out = CellStat {
            samples: self.n,
            mean,
            rms,
            rms_ratio: rms / floor,
            p_value: 1.0,
            ..CellStat::default()
        };
        if nb < 8 {
            return out;
        }
        // Batch means, weighted by batch size.
        let (mut vm, mut vs) = (0.0, 0.0);
        for (c, s, q) in &self.batches {
            let w = *c as f64;
            let dm = s / w - mean;
            let ds = q / w - ms;
            vm += w * w * dm * dm;
            vs += w * w * ds * ds;
        }
        let scale = nb as f64 / ((nb - 1) as f64 * n * n);
        let se_m = (vm * scale).sqrt().max(floor * 1e-3 / n.sqrt());
        let se_s = (vs * scale).sqrt().max(floor * floor * 1e-3 / n.sqrt());
        out.z_bias = mean.abs() / se_m;
        out.z_excess = (ms - floor * floor) / se_s;
        let z = out.z_bias.max(out.z_excess);
        out.p_value = (2.0 * normal_sf(z)).min(1.0);
        out.flagged = (out.z_bias > z_crit && mean.abs() > 0.3 * floor)
            || (out.z_excess > z_crit && rms > 1.3 * floor);
        out
    }
}

fn bin_of(edges: &[f64], v: f64) -> Option<usize> {
    (0..edges.len() - 1).find(|&b| v >= edges[b] && v < edges[b + 1])
}

/// Bin edges of each variable for this recording.
fn edges_for(prep: &Prepared, rows: &[usize]) -> Vec<Vec<f64>> {
    let duration = prep.t[prep.n - 1] - prep.t[0];
    let mut rates: Vec<f64> = rows.iter().map(|&k| prep.env[k].command_rate).collect();
    rates.sort_by(f64::total_cmp);
    let q = |f: f64| rates[((rates.len() - 1) as f64 * f) as usize];
    let mut rate_edges = vec![-1.0, q(0.2), q(0.4), q(0.6), q(0.8), 1e9];
    rate_edges.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
    vec![
        HEIGHT_EDGES.to_vec(),
        VARPHI_EDGES.to_vec(),
        vec![-1.0, 0.3, 0.7, 1.2, 2.0, 3.0, 1e9],
        vec![-1.0, 0.4, 0.5, 0.6, 0.7, 0.8, 1e9],
        (0..=6)
            .map(|i| {
                duration * f64::from(i) / 6.0 - if i == 0 { 1.0 } else { 0.0 }
                    + if i == 6 { 1.0 } else { 0.0 }
            })
            .collect(),
        rate_edges,
    ]
}

fn label(var: usize, a: f64, b: f64) -> String {
    let unit = ["m", "deg", "m/s", "", "s", "1/s"][var];
    let name = VARIABLES[var];
    match (a <= -0.5, b >= 1e8) {
        (true, true) => format!("{name} any"),
        (true, false) => format!("{name} < {b:.2} {unit}"),
        (false, true) => format!("{name} >= {a:.2} {unit}"),
        (false, false) => format!("{name} {a:.2}..{b:.2} {unit}"),
    }
    .trim_end()
    .to_string()
}

/// Locates the residual `resid` (6 per row) over the rows in `rows`.
pub fn locate(prep: &Prepared, resid: &[f64], rows: &[usize]) -> Location {
    let edges = edges_for(prep, rows);
    let nh = HEIGHT_EDGES.len() - 1;
    let nv = VARPHI_EDGES.len() - 1;
    let tests: usize = 6 * (edges.iter().map(|e| e.len() - 1).sum::<usize>() + nh * nv);
    let z_crit = normal_isf(ALPHA / (2.0 * tests as f64));
    let mut var_acc: Vec<Vec<Vec<Acc>>> = edges
        .iter()
        .map(|e| {
            (0..e.len() - 1)
                .map(|_| (0..6).map(|_| Acc::new()).collect())
                .collect()
        })
        .collect();
    let mut heat_acc: Vec<Vec<Vec<Acc>>> = (0..nh)
        .map(|_| {
            (0..nv)
                .map(|_| (0..6).map(|_| Acc::new()).collect())
                .collect()
        })
        .collect();
    let t0 = prep.t[0];
    for &k in rows {
        let env = &prep.env[k];
        let batch = ((prep.t[k] - t0) / BATCH) as i64;
        let hb = bin_of(&HEIGHT_EDGES, env.height);
        let vb = bin_of(&VARPHI_EDGES, env.varphi.to_degrees());
        for c in 0..6 {
            let r = resid[6 * k + c];
            for (v, e) in edges.iter().enumerate() {
                if let Some(b) = bin_of(e, value(env, v)) {
                    var_acc[v][b][c].push(batch, r);
                }
            }
            if let (Some(h), Some(p)) = (hb, vb) {
                heat_acc[h][p][c].push(batch, r);
            }
        }
    }
    let floor = prep.floor;
    let heat: Vec<Vec<[CellStat; 6]>> = heat_acc
        .iter()
        .map(|row| {
            row.iter()
                .map(|cell| std::array::from_fn(|c| cell[c].stat(floor[c], z_crit)))
                .collect()
        })
        .collect();
    let mut bins = Vec::new();
    let mut located = Vec::new();
    let mut channels = Vec::new();
    for (v, e) in edges.iter().enumerate() {
        let stats: Vec<[CellStat; 6]> = var_acc[v]
            .iter()
            .map(|cell| std::array::from_fn(|c| cell[c].stat(floor[c], z_crit)))
            .collect();
        for c in 0..6 {
            // Merge neighbouring flagged bins into one range.
            let mut b = 0;
            while b < stats.len() {
                if !stats[b][c].flagged {
                    b += 1;
                    continue;
                }
                let start = b;
                while b < stats.len() && stats[b][c].flagged {
                    b += 1;
                }
                let part = &stats[start..b];
                let n: usize = part.iter().map(|s| s[c].samples).sum();
                let nf = n.max(1) as f64;
                let mean = part
                    .iter()
                    .map(|s| s[c].mean * s[c].samples as f64)
                    .sum::<f64>()
                    / nf;
                let ms = part
                    .iter()
                    .map(|s| s[c].rms * s[c].rms * s[c].samples as f64)
                    .sum::<f64>()
                    / nf;
                let p = part.iter().map(|s| s[c].p_value).fold(1.0, f64::min);
                located.push(Located {
                    channel: CHANNELS[c].into(),
                    variable: VARIABLES[v].into(),
                    from: e[start],
                    to: e[b],
                    region: label(v, e[start], e[b]),
                    samples: n,
                    mean,
                    rms: ms.sqrt(),
                    rms_ratio: ms.sqrt() / floor[c],
                    p_value: p,
                });
                if !channels.contains(&c) {
                    channels.push(c);
                }
            }
        }
        bins.push((VARIABLES[v].to_string(), e.clone(), stats));
    }
    for (h, row) in heat.iter().enumerate() {
        for (p, cell) in row.iter().enumerate() {
            for c in 0..6 {
                if cell[c].flagged {
                    located.push(Located {
                        channel: CHANNELS[c].into(),
                        variable: "height x varphi".into(),
                        from: HEIGHT_EDGES[h],
                        to: HEIGHT_EDGES[h + 1],
                        region: format!(
                            "{}, {}",
                            label(0, HEIGHT_EDGES[h], HEIGHT_EDGES[h + 1]),
                            label(1, VARPHI_EDGES[p], VARPHI_EDGES[p + 1])
                        ),
                        samples: cell[c].samples,
                        mean: cell[c].mean,
                        rms: cell[c].rms,
                        rms_ratio: cell[c].rms_ratio,
                        p_value: cell[c].p_value,
                    });
                    if !channels.contains(&c) {
                        channels.push(c);
                    }
                }
            }
        }
    }
    channels.sort_unstable();
    Location {
        located,
        heat,
        bins,
        channels,
        z_critical: z_crit,
    }
}

impl Location {
    /// Whether row `k` lies in a flagged (height, varphi) cell of any
    /// channel; without flagged cells, in any flagged bin of any variable.
    pub fn region_mask(&self, prep: &Prepared) -> Vec<bool> {
        let any_heat = self
            .heat
            .iter()
            .flatten()
            .any(|c| c.iter().any(|s| s.flagged));
        (0..prep.n)
            .map(|k| {
                let env = &prep.env[k];
                if any_heat {
                    let h = bin_of(&HEIGHT_EDGES, env.height);
                    let v = bin_of(&VARPHI_EDGES, env.varphi.to_degrees());
                    matches!((h, v), (Some(h), Some(v)) if self.heat[h][v].iter().any(|s| s.flagged))
                } else {
                    self.bins.iter().enumerate().any(|(vi, (_, e, stats))| {
                        bin_of(e, value(env, vi)).is_some_and(|b| stats[b].iter().any(|s| s.flagged))
                    })
                }
            })
            .collect()
    }
}
