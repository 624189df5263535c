//! docs/parameters.md is generated from the parameters' declarations
//! (`cargo run -p atmo-daemon -- check --params > docs/parameters.md`):
//! it must be the current one, so that the reference never says what a
//! declaration no longer does.

use atmo_daemon::reference::parameter_reference;
use atmo_flight::settings::FlightSettings;

#[test]
fn docs_parameters_md_is_generated_from_the_declarations() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/parameters.md");
    let committed = std::fs::read_to_string(path).unwrap_or_default();
    assert!(
        committed == parameter_reference(),
        "docs/parameters.md is stale: run `cargo run -p atmo-daemon -- check --params > docs/parameters.md`"
    );
}

#[test]
fn every_parameter_has_a_doc_and_each_flight_key_is_listed_once() {
    use atmo_core::params::Params as _;
    let params = FlightSettings::params();
    let mut keys: Vec<&str> = params.iter().map(|p| p.key.as_str()).collect();
    let n = keys.len();
    keys.sort_unstable();
    keys.dedup();
    assert_eq!(keys.len(), n, "a key listed twice");
    let reference = parameter_reference();
    let undocumented: Vec<&str> = reference
        .lines()
        .filter(|l| l.starts_with("| `") && l.ends_with("|  |"))
        .collect();
    assert!(undocumented.is_empty(), "no doc: {undocumented:#?}");
    for p in &params {
        assert!(
            reference.contains(&format!("| `{}` |", p.key)),
            "{} missing",
            p.key
        );
    }
    let min_interval = params
        .iter()
        .find(|p| p.key == "observer.min_interval")
        .map(|p| (p.default, p.range, p.unit));
    assert_eq!(min_interval, Some((Some("0.0"), Some("0.0..=0.05"), "s")));
}
