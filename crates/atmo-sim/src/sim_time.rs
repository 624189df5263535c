//! The simulated clock's unit: plant time in ns (shared by the simulated
//! I/O and the fault injector).

/// Plant time `t` (s) in ns, rounded; negative times are 0.
pub fn time_ns(t: f64) -> u64 {
    (t.max(0.0) * 1e9).round() as u64
}
