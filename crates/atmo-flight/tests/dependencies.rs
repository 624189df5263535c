//! The flight library links no transport, no plotting and no simulator
//! plant; the physics and analysis crates link no transport either. Read
//! from `cargo tree` of the normal (non-dev) dependencies, so a dependency
//! added to any of them later fails here with its path.

use std::process::Command;

/// The crates' normal dependency tree, one package per line.
fn normal_tree(package: &str) -> String {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args(["tree", "-e", "normal", "--prefix", "none", "-p", package])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree -p {package}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn assert_free_of(package: &str, forbidden: &[&str]) {
    let tree = normal_tree(package);
    let found: Vec<&str> = tree
        .lines()
        .filter(|line| {
            let name = line.split_whitespace().next().unwrap_or_default();
            forbidden.contains(&name)
        })
        .collect();
    assert!(found.is_empty(), "{package} depends on {found:?}");
    assert!(tree.lines().count() > 1, "{package}: an empty tree");
}

const TRANSPORTS: [&str; 3] = ["ros2-client", "rustdds", "iceoryx2"];

#[test]
fn the_flight_library_links_no_transport_plotting_or_plant() {
    let mut forbidden = TRANSPORTS.to_vec();
    forbidden.extend(["plotters", "atmo-plant"]);
    assert_free_of("atmo-flight", &forbidden);
}

#[test]
fn the_physics_and_analysis_crates_link_no_transport() {
    for package in ["atmo-core", "atmo-mpc", "atmo-plant", "atmo-explain"] {
        assert_free_of(package, &TRANSPORTS);
    }
}
