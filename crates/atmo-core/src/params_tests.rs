use std::path::Path;

use crate::config_file::{Checker, parse_toml};
use crate::params::Params as _;

crate::params! {
    /// A nested table.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Gains {
        /// Proportional gain.
        pub kp: f64, range 0.0..=10.0;
        /// Per-axis limits.
        pub limits: [f64; 3] = [1.0; 3], range 0.0..=5.0, unit "N";
    }
}

crate::params! {
    /// A table as a file first had it.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Before {
        /// Largest speed.
        pub max_speed: f64, range 0.0..=2.0, unit "m/s";
        /// Below this, a descent.
        pub threshold: f64, range 0.0..=*max_speed, unit "m/s";
        /// Named `loop` in the file.
        pub rate: f64, key "loop", range 1.0..=1000.0, unit "Hz";
        /// The gains.
        pub gains: Gains;
        /// Optional name.
        pub name: Option<String> = None;
    }
    check |_table, c, prefix| {
        if *rate > 500.0 && *max_speed > 1.0 {
            return Err(c.fail(
                &crate::params::key(prefix, "loop"),
                "at most 500 Hz above 1 m/s",
                rate,
            ));
        }
        Ok(())
    }
}

crate::params! {
    /// The same table after a key was added, with the default that
    /// reproduces what files without it meant.
    #[derive(Debug, Clone, PartialEq)]
    pub struct After {
        /// Largest speed.
        pub max_speed: f64, range 0.0..=2.0, unit "m/s";
        /// Below this, a descent.
        pub threshold: f64, range 0.0..=*max_speed, unit "m/s";
        /// Named `loop` in the file.
        pub rate: f64, key "loop", range 1.0..=1000.0, unit "Hz";
        /// The gains.
        pub gains: Gains;
        /// Optional name.
        pub name: Option<String> = None;
        /// Added later: 0 keeps the old behaviour.
        pub min_interval: f64 = 0.0, range 0.0..=0.05, unit "s";
    }
}

const OLD_FILE: &str = "max_speed = 1.0\nthreshold = 0.5\nloop = 150.0\n\n[gains]\nkp = 2.0\n";

fn parse<T: serde::de::DeserializeOwned>(text: &str) -> crate::Result<T> {
    parse_toml(text, Path::new("t.toml"))
}

fn check<T: crate::params::Params>(t: &T) -> String {
    t.check(&Checker::new(Path::new("t.toml")), "")
        .map_or_else(|e| e.to_string(), |()| "ok".into())
}

#[test]
fn an_old_file_reads_the_added_key_as_its_default() {
    let before: Before = parse(OLD_FILE).unwrap();
    let after: After = parse(OLD_FILE).unwrap();
    assert_eq!(after.min_interval, 0.0);
    assert_eq!(
        (after.max_speed, after.threshold, after.rate, &after.gains),
        (
            before.max_speed,
            before.threshold,
            before.rate,
            &before.gains
        )
    );
    assert_eq!(after.gains.limits, [1.0; 3]);
    assert_eq!(check(&after), "ok");
    let set: After = parse(&OLD_FILE.replace("loop", "min_interval = 0.01\nloop")).unwrap();
    assert_eq!(set.min_interval, 0.01);
}

#[test]
fn unknown_repeated_and_missing_keys_are_refused_with_their_path() {
    let e = parse::<Before>(&format!("{OLD_FILE}extra = 1\n"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t.toml:7") && e.contains("gains.extra") && e.contains("unknown field"),
        "{e}"
    );
    let e = parse::<Before>(&OLD_FILE.replace("threshold = 0.5\n", ""))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing field `threshold`"), "{e}");
    let e = parse::<Before>(&OLD_FILE.replace("kp = 2.0\n", ""))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("gains") && e.contains("missing field `kp`"),
        "{e}"
    );
    let e = parse::<Before>(&OLD_FILE.replace("[gains]", "[gains]\nkp = 1.0"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("kp"), "{e}");
    let e = parse::<Before>(&OLD_FILE.replace("loop = 150.0", "loop = \"fast\""))
        .unwrap_err()
        .to_string();
    assert!(e.contains("t.toml:3") && e.contains("`loop`"), "{e}");
}

#[test]
fn ranges_name_the_full_key_unit_and_value() {
    let mut b: Before = parse(OLD_FILE).unwrap();
    b.threshold = 1.5;
    assert_eq!(
        check(&b),
        "t.toml: key `threshold`: expected a value in [0, 1] m/s, got 1.5"
    );
    b.threshold = 0.5;
    b.gains.limits[2] = 9.0;
    assert_eq!(
        check(&b),
        "t.toml: key `gains.limits[2]`: expected a value in [0, 5] N, got 9"
    );
    b.gains.limits[2] = 1.0;
    b.rate = f64::NAN;
    assert_eq!(
        check(&b),
        "t.toml: key `loop`: expected a value in [1, 1000] Hz, got NaN"
    );
    b.rate = 600.0;
    b.max_speed = 1.5;
    assert_eq!(
        check(&b),
        "t.toml: key `loop`: expected at most 500 Hz above 1 m/s, got 600"
    );
}

#[test]
fn the_parameter_table_lists_every_key_once() {
    let params = After::params();
    let keys: Vec<&str> = params.iter().map(|p| p.key.as_str()).collect();
    assert_eq!(
        keys,
        [
            "max_speed",
            "threshold",
            "loop",
            "gains.kp",
            "gains.limits",
            "name",
            "min_interval"
        ]
    );
    let limits = &params[4];
    assert_eq!(limits.default, Some("[1.0; 3]"));
    assert_eq!(limits.range, Some("0.0..=5.0"));
    assert_eq!(limits.unit, "N");
    assert_eq!(limits.doc_line(), "Per-axis limits.");
    assert_eq!(params[0].default, None);
    assert_eq!(params[5].range, None);
}
