//! The plant benchmark's four cases, shared by the criterion bench
//! `plant` and the `effect_cost` example (included with `#[path]`).

use atmo_core::RobotConfig;
use atmo_core::model::{Input, Model, State, idx};
use atmo_plant::config::{PlantConfig, TerrainConfig};
use atmo_plant::plant::{Command, InitialState, Plant};

/// Steps per timed run: 1 s of simulated time at dt = 1 ms.
pub const STEPS: u64 = 1000;

/// A plant at `height` m and `tilt` rad at trim thrust, or (`on_ground`)
/// standing on its wheels on flat ground after 1 s of settling.
pub fn plant(config: &PlantConfig, height: f64, tilt: f64, on_ground: bool) -> Plant {
    let robot = RobotConfig::atmo();
    let body = Model::new(&robot).at_tilt(tilt);
    let mut x = State::zeros();
    x[idx::Z] = if on_ground {
        // Wheels just touching flat ground at z = 0.
        -(body.rotor_position[0].z + robot.wheels.radius + 1e-4)
    } else {
        -height
    };
    let initial = InitialState {
        state: x,
        tilt,
        thrust: if on_ground {
            Input::zeros()
        } else {
            body.hover_trim()
        },
    };
    let mut p = Plant::new(&robot, config, &TerrainConfig::flat(0.0), &initial, 1)
        .expect("built-in configs are valid");
    if on_ground {
        p.advance(&Command::idle(), 1.0).expect("settles");
    }
    p
}

/// The drive command of the driving case: both sides at 4 rad/s.
pub fn drive_command() -> Command {
    let mut cmd = Command::idle();
    cmd.wheel_rates.left = 4.0;
    cmd.wheel_rates.right = 4.0;
    cmd
}

/// One case: a plant to copy and the command at step k.
pub struct Case {
    pub name: &'static str,
    pub plant: Plant,
    pub command: Box<dyn Fn(u64) -> Command>,
}

/// hover, morphing, driving with every effect on; ideal with every effect off.
pub fn cases() -> Vec<Case> {
    let robot = RobotConfig::atmo();
    let full = PlantConfig::full();
    let trim = Model::new(&robot).at_tilt(0.0).hover_trim();
    let trim_low = Model::new(&robot).at_tilt(0.3).hover_trim();
    vec![
        // In the air at 1.5 m (ground effect, drag, wind, sensors... all on;
        // B is higher than any contact point reaches, so no contact is evaluated).
        Case {
            name: "hover",
            plant: plant(&full, 1.5, 0.0, false),
            command: Box::new(move |_| Command::rotors(trim)),
        },
        // Morphing near the ground: the tilt moves every step, so the
        // composite body is interpolated on the tilt grid and the
        // ground-effect slice recomputed every step.
        Case {
            name: "morphing",
            plant: plant(&full, 0.6, 0.3, false),
            command: Box::new(move |k| {
                let mut cmd = Command::rotors(trim_low);
                cmd.tilt_rate = if k < STEPS / 2 { 0.39 } else { -0.39 };
                cmd
            }),
        },
        // Driving on four wheel contacts.
        Case {
            name: "driving",
            plant: plant(&full, 0.0, std::f64::consts::FRAC_PI_2, true),
            command: Box::new(|_| drive_command()),
        },
        // Reference: every effect off (atmo-core's RK4 inside the plant).
        Case {
            name: "ideal",
            plant: plant(&PlantConfig::ideal(), 1.5, 0.0, false),
            command: Box::new(move |_| Command::rotors(trim)),
        },
    ]
}
