//! The shipped Foxglove layout is valid JSON, every panel in the layout tree
//! is configured, and every message path names a field of the message on
//! its topic (so a renamed field cannot silently empty a plot).
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeSet;

use atmo_io::msg::{MpcStatus, RosMessage, definition};

fn field_names(type_name: &str) -> BTreeSet<String> {
    definition(type_name)
        .unwrap()
        .lines()
        .map(|l| l.split('#').next().unwrap().trim())
        .filter(|l| !l.is_empty() && !l.contains('='))
        .filter_map(|l| l.split_whitespace().nth(1).map(str::to_string))
        .collect()
}

fn leaves(node: &serde_json::Value, out: &mut Vec<String>) {
    match node {
        serde_json::Value::String(id) => out.push(id.clone()),
        serde_json::Value::Object(map) => {
            leaves(&map["first"], out);
            leaves(&map["second"], out);
        }
        other => panic!("bad layout node {other}"),
    }
}

#[test]
fn layout_paths_name_real_fields() {
    let text = include_str!("../../../foxglove/atmo_layout.json");
    let layout: serde_json::Value = serde_json::from_str(text).unwrap();
    let configs = layout["configById"].as_object().unwrap();
    let mut panels = Vec::new();
    leaves(&layout["layout"], &mut panels);
    for panel in &panels {
        assert!(configs.contains_key(panel), "{panel} has no config");
    }
    let status_fields = field_names(MpcStatus::TYPE_NAME);
    let mut plotted = BTreeSet::new();
    for (id, config) in configs {
        let paths = config["paths"].as_array().cloned().unwrap_or_default();
        for path in paths {
            let value = path["value"].as_str().unwrap();
            let rest = value
                .strip_prefix("/atmo/status.")
                .unwrap_or_else(|| panic!("{id}: {value}"));
            let field = rest.split(['[', '.']).next().unwrap();
            assert!(
                status_fields.contains(field),
                "{id}: {value}: no field `{field}`"
            );
            plotted.insert(field.to_string());
        }
    }
    for wanted in ["height", "varphi", "alpha", "thrust", "mode"] {
        assert!(plotted.contains(wanted), "the layout must plot {wanted}");
    }
}
