//! The version of the configuration's meaning, and the migrations that
//! keep every older flight log replayable.
//!
//! A key added with a default that reproduces what files without it flew
//! needs no new version (`atmo_core::params!`): an older text parses as
//! it flew. [`CONFIG_SCHEMA_VERSION`] is raised when a key is removed or
//! its meaning changes; a flight log records the version it was written
//! with (metadata `atmo.config`, key `schema_version`) and a replay
//! migrates an older text here, in the library, saying what it changed.
//!
//! Versions:
//! - 1: the flare of a hold and a commit by slowness, time or predicted
//!   impact (`[flare]` keys `hold_band`, `commit_speed`, ...). Logs of it
//!   do not record their version: a log without one whose `[flare]` lacks
//!   `impact_speed_max` is of version 1.
//! - 2: the flare's one decision on a predicted touchdown with its error.

use toml_edit::{DocumentMut, InlineTable, Item, Table, value};

/// The configuration schema this build reads and writes.
pub const CONFIG_SCHEMA_VERSION: u32 = 2;

/// The key of the version in the log's configuration metadata.
pub const SCHEMA_VERSION_KEY: &str = "schema_version";

/// The `[flare]` keys version 1 and 2 share, with the same meaning.
const FLARE_KEPT: [&str; 2] = ["hold_clearance", "time_constant"];

/// Why a text could not be brought to [`CONFIG_SCHEMA_VERSION`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SchemaError {
    /// Written by a newer build: its keys may mean what this one cannot.
    Newer(u32),
    /// A recorded version that is not a number.
    Unreadable(String),
    /// The flight settings' text is not TOML.
    Toml(String),
}

impl std::fmt::Display for SchemaError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Newer(v) => write!(
                f,
                "its configuration is of schema version {v}, newer than this build's \
                 {CONFIG_SCHEMA_VERSION}: replay it with a build that knows version {v}"
            ),
            Self::Unreadable(v) => write!(
                f,
                "`{SCHEMA_VERSION_KEY}` = `{v}` is not a schema version (a whole number)"
            ),
            Self::Toml(e) => write!(f, "the flight settings are not TOML: {e}"),
        }
    }
}

/// The version of a logged configuration: the recorded one, or for a log
/// that records none, the one its flight settings' text says.
///
/// # Errors
/// A recorded version that is not a number or is newer than this build's.
pub fn logged_version(recorded: Option<&str>, flight_text: &str) -> Result<u32, SchemaError> {
    let version = if let Some(v) = recorded {
        v.trim()
            .parse()
            .map_err(|_| SchemaError::Unreadable(v.to_string()))?
    } else {
        // A text that is not TOML is left to the settings' parser, whose
        // error names the line.
        let Ok(doc) = flight_text.parse::<DocumentMut>() else {
            return Ok(CONFIG_SCHEMA_VERSION);
        };
        let flare_v2 = doc
            .get("flare")
            .and_then(Item::as_table_like)
            .is_some_and(|t| t.contains_key("impact_speed_max"));
        if flare_v2 { 2 } else { 1 }
    };
    if version > CONFIG_SCHEMA_VERSION {
        return Err(SchemaError::Newer(version));
    }
    Ok(version)
}

/// Brings the flight settings' `text` of schema `version` to
/// [`CONFIG_SCHEMA_VERSION`]: the new text (comments kept) and one line
/// per change, saying what the replay cannot reproduce.
///
/// # Errors
/// A text that is not TOML.
pub fn migrate_flight(text: &str, version: u32) -> Result<(String, Vec<String>), SchemaError> {
    if version >= CONFIG_SCHEMA_VERSION {
        return Ok((text.to_string(), Vec::new()));
    }
    let mut doc: DocumentMut = text
        .parse()
        .map_err(|e: toml_edit::TomlError| SchemaError::Toml(e.to_string()))?;
    let mut notes = Vec::new();
    if version < 2
        && let Some(flare) = doc.get_mut("flare").and_then(Item::as_table_mut)
    {
        notes.push(flare_1_to_2(flare));
    }
    Ok((doc.to_string(), notes))
}

/// Version 1's `[flare]` to version 2's: the hold keeps its clearance and
/// approach; the decision's keys take the values version 2 shipped with.
fn flare_1_to_2(flare: &mut Table) -> String {
    let removed: Vec<String> = flare
        .iter()
        .map(|(k, _)| k.to_string())
        .filter(|k| !FLARE_KEPT.contains(&k.as_str()))
        .collect();
    for key in &removed {
        flare.remove(key);
    }
    let error = |mean: f64, spread: f64| {
        let mut t = InlineTable::new();
        t.insert("mean", mean.into());
        t.insert("spread", spread.into());
        value(t)
    };
    flare["impact_speed_max"] = value(0.4);
    flare["touchdown_tilt_min_deg"] = value(64.0);
    flare["impact_speed_error"] = error(-0.100, 0.058);
    flare["touchdown_tilt_error_deg"] = error(-0.37, 1.00);
    format!(
        "[flare] of schema 1 (a hold committed by slowness, time or predicted impact) \
         replaced by schema 2's decision on a predicted touchdown (removed: {}): \
         ticks after a flare's commit do not replay as flown",
        removed.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    const V1_FLARE: &str = "mpc_preset = \"fig5\"\n\n[flare]\nenabled = true\n\
        hold_clearance = 0.03 # m\ntime_constant = 0.25\nhold_band = 0.01\n\
        commit_speed = 0.03\n\n[loop]\nrate_hz = 150.0\n";

    #[test]
    fn an_unversioned_log_is_versioned_by_its_flare() {
        assert_eq!(logged_version(None, V1_FLARE), Ok(1));
        let shipped = include_str!("../../../config/flight.toml");
        assert_eq!(logged_version(None, shipped), Ok(2));
        assert_eq!(logged_version(Some("2"), V1_FLARE), Ok(2));
    }

    #[test]
    fn a_newer_or_unreadable_version_is_refused_by_name() {
        let next = (CONFIG_SCHEMA_VERSION + 1).to_string();
        let e = logged_version(Some(&next), "").unwrap_err().to_string();
        assert!(
            e.contains(&format!("schema version {next}, newer than this build's")),
            "{e}"
        );
        let e = logged_version(Some("two"), "").unwrap_err().to_string();
        assert!(e.contains("`schema_version` = `two`"), "{e}");
    }

    #[test]
    fn version_1_flare_keeps_its_hold_and_takes_the_decision() {
        let (text, notes) = migrate_flight(V1_FLARE, 1).unwrap();
        let doc: DocumentMut = text.parse().unwrap();
        let flare = doc["flare"].as_table().unwrap();
        assert_eq!(flare["hold_clearance"].as_float(), Some(0.03));
        assert_eq!(flare["time_constant"].as_float(), Some(0.25));
        assert_eq!(flare["impact_speed_max"].as_float(), Some(0.4));
        assert!(!flare.contains_key("hold_band") && !flare.contains_key("enabled"));
        assert!(
            text.contains("hold_clearance = 0.03 # m"),
            "comments kept: {text}"
        );
        assert_eq!(notes.len(), 1);
        assert!(
            notes[0].contains("removed: enabled, hold_band, commit_speed"),
            "{}",
            notes[0]
        );
        assert_eq!(logged_version(None, &text), Ok(2));
        // A current text is left as it is.
        assert_eq!(migrate_flight(&text, 2).unwrap(), (text.clone(), vec![]));
    }
}
