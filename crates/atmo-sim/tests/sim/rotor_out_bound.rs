//! How soft a stopped rotor's landing could be at all (a measurement, not
//! a check): from the flight's plant at the fault's onset (the flight's
//! commands replayed into a plant up to there, bit for bit: its wind and
//! noise the flight's), with the rotor
//! known stopped from that instant, a cross-entropy search over open-loop
//! commands (the three rotors left and the tilt rate, piecewise constant)
//! looks for the softest touchdown the plant allows, from two starts: the
//! commands the flight stack flew (replayed open loop they land harder
//! than the flight did) and the stopped rotor's diagonal partner off. A
//! search, not a proof: a command it does not find may exist
//! (docs/decisions/2026-12-07-stopped-rotor-bound.md).
//!
//! `ROTOR_SEEDS=0,7000001 BOUND_ONSETS=flight,transition cargo test
//! --release -p atmo-sim --test sim -- --ignored stopped_rotor_bound
//! --nocapture`; `BOUND_FROM=detection` starts the search where the
//! flight stack told the rotor stopped (the flight until then flown by the
//! stack, closed loop): what is left to find once the stack knows.
#![allow(clippy::unwrap_used, reason = "test")]

use atmo_core::Input;
use atmo_core::model::{idx, level_cosine};
use atmo_flight::Mode;
use atmo_plant::plant::N_CONTACTS;
use atmo_plant::{Command, CrashKind, Plant};
use atmo_sim::closed_loop::TickRecord;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::actuator_faults::{detected, seeded_scenario};
use super::faults::fly_scenario;
use atmo_flight::actuator_monitor::Detected;

/// Length of one piece of the open-loop command, s.
const SEGMENT: f64 = 0.08;
/// Pieces searched; the last is held to the rollout's end.
const SEGMENTS: usize = 25;
/// Searched inputs per piece: the three rotors left, the tilt rate.
const PER_SEGMENT: usize = 4;
/// The rollout ends this long after the searched pieces (s).
const SETTLE: f64 = 1.0;
const POPULATION: usize = 256;
const ELITES: usize = 16;
const ITERATIONS: usize = 150;

/// What one open-loop command did.
#[derive(Debug, Clone, Copy)]
struct Outcome {
    /// Lower is softer (see [`rollout`]).
    score: f64,
    crash: Option<CrashKind>,
    /// Fastest wheel impact, m/s (a wheel's approach speed as it touches).
    wheel_impact: f64,
    /// First contact's approach speed, m/s.
    first_touch: Option<f64>,
    /// Largest tilt of the body from level while a contact touched, deg.
    tipped_deg: f64,
    /// Whether something touched the ground at all.
    touched: bool,
}

/// The commands of parameter vector `x` at `time` since the onset.
fn command(x: &[f64], failed: usize, time: f64, tilt_rate_max: f64) -> Command {
    let k = ((time / SEGMENT) as usize).min(SEGMENTS - 1);
    let p = &x[k * PER_SEGMENT..(k + 1) * PER_SEGMENT];
    let mut rotors = Input::zeros();
    let mut j = 0;
    for r in 0..4 {
        if r != failed {
            rotors[r] = p[j].clamp(0.0, 1.0);
            j += 1;
        }
    }
    let mut c = Command::rotors(rotors);
    c.tilt_rate = p[3].clamp(-1.0, 1.0) * tilt_rate_max;
    c
}

/// The plant of the flight `ticks` flew, stepped through its commands up
/// to the tick at `at` (the failed rotor's command zeroed from the onset
/// tick at `onset` on, as the fault did): the wind's gust and turbulence and
/// every noise drawn at the same times as in the flight.
fn flown_plant(
    scenario: &atmo_sim::Scenario,
    ticks: &[TickRecord],
    onset: f64,
    failed: usize,
    at: f64,
) -> Plant {
    let mut plant = scenario.build_plant().unwrap();
    let mut command = Command::idle();
    for t in ticks {
        while plant.time() < t.time - 1e-9 {
            let (force, torque) = scenario.disturbance_at(plant.time());
            plant.set_external_wrench(force, torque).unwrap();
            plant.step(&command).unwrap();
        }
        if t.time >= at - 1e-9 {
            break;
        }
        let mut rotors = Input::from(t.outputs.thrust);
        if t.time >= onset - 1e-9 {
            rotors[failed] = 0.0;
        }
        command = Command {
            rotors,
            tilt_rate: t.outputs.tilt_velocity,
            wheel_rates: t.outputs.wheel_rates,
        };
    }
    plant
}

/// Flies `x` open loop from `start`. The score is the fastest approach
/// speed of any contact as it touches (wheels and base corners, m/s) and
/// the body's largest tilt from level while touching (per 30 deg), plus 10
/// for a crash by the plant's rule and 20 if nothing touched by the end: a
/// landing without a crash always scores under 10.
fn rollout(start: &Plant, x: &[f64], failed: usize, tilt_rate_max: f64) -> Outcome {
    let mut p = start.clone();
    let t0 = p.time();
    let end = SEGMENT * SEGMENTS as f64 + SETTLE;
    let mut was = [false; N_CONTACTS];
    let (mut wheel_impact, mut any_impact, mut tipped) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut first_touch = None;
    while p.time() - t0 < end && p.crash().is_none() {
        p.step(&command(x, failed, p.time() - t0, tilt_rate_max))
            .unwrap();
        let mut touching = false;
        for (i, c) in p.contacts().iter().enumerate() {
            if c.touching && !was[i] {
                any_impact = any_impact.max(c.approach_speed);
                first_touch.get_or_insert(c.approach_speed);
                if i < 4 {
                    wheel_impact = wheel_impact.max(c.approach_speed);
                }
            }
            touching |= c.touching;
            was[i] = c.touching;
        }
        if touching {
            tipped = tipped.max(level_cosine(&p.state()).acos().to_degrees());
        }
    }
    let crash = p.crash().and_then(|e| match e.kind {
        atmo_plant::EventKind::Crash(k) => Some(k),
        _ => None,
    });
    let touched = first_touch.is_some();
    let mut score = any_impact + tipped / 30.0;
    if crash.is_some() {
        score += 10.0;
    }
    if !touched {
        score += 20.0;
    }
    Outcome {
        score,
        crash,
        wheel_impact,
        first_touch,
        tipped_deg: tipped,
        touched,
    }
}

/// The flight stack's commands after `onset` as a parameter vector (each
/// piece the mean of the ticks in it; the stopped rotor left out).
fn shipped_commands(
    ticks: &[TickRecord],
    onset: f64,
    failed: usize,
    tilt_rate_max: f64,
) -> Vec<f64> {
    let mut x = vec![0.0; SEGMENTS * PER_SEGMENT];
    for k in 0..SEGMENTS {
        let from = onset + k as f64 * SEGMENT;
        let piece: Vec<&TickRecord> = ticks
            .iter()
            .filter(|t| t.time >= from && t.time < from + SEGMENT)
            .collect();
        if piece.is_empty() {
            // After the shipped flight's end: hold the piece before.
            if k > 0 {
                let (a, b) = x.split_at_mut(k * PER_SEGMENT);
                b[..PER_SEGMENT].copy_from_slice(&a[(k - 1) * PER_SEGMENT..]);
            }
            continue;
        }
        let n = piece.len() as f64;
        let mut j = 0;
        for r in 0..4 {
            if r != failed {
                x[k * PER_SEGMENT + j] = piece.iter().map(|t| t.outputs.thrust[r]).sum::<f64>() / n;
                j += 1;
            }
        }
        x[k * PER_SEGMENT + 3] =
            piece.iter().map(|t| t.outputs.tilt_velocity).sum::<f64>() / n / tilt_rate_max;
    }
    x
}

/// The other start of the search: after the first `fixed` pieces of `x0`,
/// the stopped rotor's diagonal partner (the other rotor turning the same
/// way, `yaw_sign`) off and the other diagonal at full thrust (no roll or
/// pitch torque: the robot falls level, turning about its z axis), the
/// tilt rising at full speed.
fn diagonal_left(x0: &[f64], fixed: usize, failed: usize, yaw_sign: &[f64; 4]) -> Vec<f64> {
    let partner = (0..4)
        .find(|&r| r != failed && yaw_sign[r] == yaw_sign[failed])
        .unwrap();
    let mut x = x0.to_vec();
    for k in fixed..SEGMENTS {
        let mut j = 0;
        for r in 0..4 {
            if r != failed {
                x[k * PER_SEGMENT + j] = if r == partner { 0.0 } else { 1.0 };
                j += 1;
            }
        }
        x[k * PER_SEGMENT + 3] = 1.0;
    }
    x
}

/// The cross-entropy search from `mean`: the best command found and what
/// it did.
fn search(
    start: &Plant,
    mean: Vec<f64>,
    fixed: usize,
    failed: usize,
    tilt_rate_max: f64,
    seed: u64,
) -> (Vec<f64>, Outcome) {
    let dim = mean.len();
    let mut mean = mean;
    // The first `fixed` pieces are the shipped ones (the detection's latency).
    let mut sigma: Vec<f64> = (0..dim)
        .map(|i| if i < fixed * PER_SEGMENT { 0.0 } else { 0.25 })
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut best = (mean.clone(), rollout(start, &mean, failed, tilt_rate_max));
    let threads = std::thread::available_parallelism().map_or(1, usize::from);
    for _ in 0..ITERATIONS {
        let mut xs: Vec<Vec<f64>> = (0..POPULATION)
            .map(|_| {
                (0..dim)
                    .map(|i| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        mean[i] + sigma[i] * z
                    })
                    .collect()
            })
            .collect();
        xs[0].clone_from(&best.0);
        let outcomes: Vec<Outcome> = std::thread::scope(|scope| {
            let chunks: Vec<_> = xs
                .chunks(POPULATION.div_ceil(threads))
                .map(|chunk| {
                    scope.spawn(move || {
                        chunk
                            .iter()
                            .map(|x| rollout(start, x, failed, tilt_rate_max))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            chunks.into_iter().flat_map(|h| h.join().unwrap()).collect()
        });
        let mut order: Vec<usize> = (0..POPULATION).collect();
        order.sort_by(|&a, &b| outcomes[a].score.total_cmp(&outcomes[b].score));
        if outcomes[order[0]].score < best.1.score {
            best = (xs[order[0]].clone(), outcomes[order[0]]);
        }
        for i in 0..dim {
            let e: Vec<f64> = order[..ELITES].iter().map(|&k| xs[k][i]).collect();
            let m = e.iter().sum::<f64>() / ELITES as f64;
            let v = e.iter().map(|v| (v - m).powi(2)).sum::<f64>() / ELITES as f64;
            mean[i] = 0.3 * mean[i] + 0.7 * m;
            if i >= fixed * PER_SEGMENT {
                sigma[i] = (0.3 * sigma[i] + 0.7 * v.sqrt()).max(0.02);
            }
        }
    }
    best
}

#[test]
#[ignore = "a measurement"]
fn stopped_rotor_bound() {
    let seeds: Vec<u64> = std::env::var("ROTOR_SEEDS").map_or(vec![0], |s| {
        s.split(',').map(|v| v.trim().parse().unwrap()).collect()
    });
    let rotors: Vec<usize> = std::env::var("BOUND_ROTORS").map_or(vec![1, 2, 3, 4], |s| {
        s.split(',').map(|v| v.trim().parse().unwrap()).collect()
    });
    // Seconds of the shipped commands kept before the search's own (the
    // detection's latency; 0: the rotor known stopped at the onset).
    let latency: f64 = std::env::var("BOUND_LATENCY").map_or(0.0, |s| s.parse().unwrap());
    let fixed = (latency / SEGMENT).ceil() as usize;
    let from_detection = std::env::var("BOUND_FROM").is_ok_and(|v| v == "detection");
    let trace = std::env::var("BOUND_TRACE").is_ok();
    let onsets = std::env::var("BOUND_ONSETS").unwrap_or_else(|_| "flight,transition".into());
    for seed in seeds {
        for onset in onsets.split(',') {
            let spec = if onset == "flight" {
                "t = 1.0"
            } else {
                "mode = \"transition\""
            };
            for &n in &rotors {
                let scenario = seeded_scenario(
                    &format!("[[faults.actuators.rotor]]\n{spec}\nrotor = {n}\nscale = 0.0"),
                    seed,
                );
                let shipped = fly_scenario(&scenario);
                let at = if onset == "flight" {
                    shipped.ticks.iter().find(|t| t.time >= 1.0)
                } else {
                    shipped
                        .ticks
                        .iter()
                        .find(|t| t.outputs.status.mode == Mode::Transition)
                }
                .unwrap();
                let onset_time = at.time;
                let at = if from_detection {
                    detected(&shipped, Detected::ROTOR_STOPPED)
                        .filter(|t| t.time >= at.time)
                        .unwrap_or_else(|| panic!("seed {seed} rotor {n}: never told stopped"))
                } else {
                    at
                };
                let tilt_rate_max = scenario.robot.limits.tilt_rate_max;
                let failed = n - 1;
                // The flight's own world: its wind, gust and noise at the
                // same times (a plant started afresh at the truth draws
                // them anew from its own clock).
                let plant = flown_plant(&scenario, &shipped.ticks, onset_time, failed, at.time);
                assert!(
                    (plant.state() - at.truth).amax() == 0.0 && plant.time() == at.time,
                    "seed {seed} rotor {n}: the replayed flight is not the flown one at {:.3} s",
                    at.time
                );
                let x0 = shipped_commands(&shipped.ticks, at.time, failed, tilt_rate_max);
                let replayed = rollout(&plant, &x0, failed, tilt_rate_max);
                let pair = diagonal_left(&x0, fixed, failed, &scenario.robot.rotor.yaw_sign);
                let (x, best) = search(&plant, x0, fixed, failed, tilt_rate_max, seed ^ n as u64);
                let (y, from_pair) =
                    search(&plant, pair, fixed, failed, tilt_rate_max, seed ^ n as u64);
                if trace {
                    print_trace(&plant, &x, failed, tilt_rate_max);
                    println!("  from the diagonal left:");
                    print_trace(&plant, &y, failed, tilt_rate_max);
                }
                let s = &shipped.summary;
                println!(
                    "seed {seed} {onset:>10} rotor {n}: {:.2} m up at {:.3} s; shipped impact {:?} crash {:?}; its commands open loop: first {:.2?} wheels {:.2} tipped {:.0} crash {:?}; best found: first {:.2?} wheels {:.2} tipped {:.0} crash {:?} touched {}",
                    at.truth_height,
                    at.time,
                    s.impact_speed_mps.map(|v| (v * 100.0).round() / 100.0),
                    s.crash_reason,
                    replayed.first_touch,
                    replayed.wheel_impact,
                    replayed.tipped_deg,
                    replayed.crash,
                    best.first_touch,
                    best.wheel_impact,
                    best.tipped_deg,
                    best.crash,
                    best.touched,
                );
                println!(
                    "    from the diagonal left: first {:.2?} wheels {:.2} tipped {:.0} crash {:?} touched {}",
                    from_pair.first_touch,
                    from_pair.wheel_impact,
                    from_pair.tipped_deg,
                    from_pair.crash,
                    from_pair.touched,
                );
            }
        }
    }
}

/// Prints the flight of command `x` from `start` every 20 ms.
fn print_trace(start: &Plant, x: &[f64], failed: usize, tilt_rate_max: f64) {
    let mut p = start.clone();
    let t0 = p.time();
    while p.time() - t0 < SEGMENT * SEGMENTS as f64 && p.crash().is_none() {
        let c = command(x, failed, p.time() - t0, tilt_rate_max);
        p.step(&c).unwrap();
        if p.steps().is_multiple_of(20) {
            let s = p.state();
            let touching = p.contacts().iter().filter(|c| c.touching).count();
            println!(
                "  {:.2} z {:.2} vz {:.2} roll {:.0} pitch {:.0} wz {:.1} tilt {:.0} u [{:.2} {:.2} {:.2} {:.2}] rate {:.2} touching {touching}",
                p.time() - t0,
                s[idx::Z],
                s[idx::VZ],
                s[idx::ROLL].to_degrees(),
                s[idx::PITCH].to_degrees(),
                s[idx::WZ],
                p.tilt().to_degrees(),
                c.rotors[0],
                c.rotors[1],
                c.rotors[2],
                c.rotors[3],
                c.tilt_rate,
            );
        }
    }
}
