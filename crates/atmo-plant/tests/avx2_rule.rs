//! The AVX2 rule of the plant's step (stated in the module docs of
//! `src/plant/step.rs`): `Plant::step` is compiled twice, portable and with
//! AVX2 + FMA, and only code inlined into it enters the AVX2 copy. So every
//! function of the step code says how it is compiled, `#[inline(always)]`
//! (in both copies) or `#[inline(never)]` (out of line on purpose), and the
//! step code calls no function of the modules outside it.
//!
//! This test reads the step modules' sources and fails listing every
//! function that says neither, every `self.method(..)` call to a method not
//! defined in the step modules, and every function imported into them from
//! a module outside them.

/// The step modules: (path, source, where the step code starts).
const STEP_FILES: [(&str, &str, Option<&str>); 7] = [
    (
        "src/plant/step.rs",
        include_str!("../src/plant/step.rs"),
        None,
    ),
    (
        "src/plant/effects.rs",
        include_str!("../src/plant/effects.rs"),
        None,
    ),
    ("src/contact.rs", include_str!("../src/contact.rs"), None),
    ("src/body.rs", include_str!("../src/body.rs"), None),
    ("src/noise.rs", include_str!("../src/noise.rs"), None),
    ("src/sensors.rs", include_str!("../src/sensors.rs"), None),
    // atmo-core's surface, the plant's truth table: the file's first half is
    // the config type, read at start-up.
    (
        "../atmo-core/src/ground_effect/table.rs",
        include_str!("../../atmo-core/src/ground_effect/table.rs"),
        Some("// AVX2 rule: from here to the end of the file, step code"),
    ),
];

/// Modules outside the step code that the step modules may import types
/// and constants from (never functions).
const OUTSIDE: [&str; 4] = [
    "super::{",
    "crate::config::",
    "crate::error::",
    "crate::plant::",
];

/// The checked part of a step file, as (line number, line): from its marker
/// (or the top) to its unit tests.
fn step_lines<'a>(source: &'a str, start: Option<&str>) -> Vec<(usize, &'a str)> {
    let mut on = start.is_none();
    let mut lines = Vec::new();
    for (i, line) in source.lines().enumerate() {
        if let Some(marker) = start
            && line.starts_with(marker)
        {
            on = true;
        }
        if line.trim_start().starts_with("#[cfg(test)]") {
            break;
        }
        if on {
            lines.push((i + 1, line));
        }
    }
    assert!(!lines.is_empty(), "marker {start:?} not found");
    lines
}

/// The name of the function a line declares, if it declares one.
fn declared_fn(line: &str) -> Option<&str> {
    let mut rest = line.trim_start();
    for prefix in ["pub(crate) ", "pub(super) ", "pub "] {
        rest = rest.strip_prefix(prefix).unwrap_or(rest);
    }
    let rest = rest.strip_prefix("const ").unwrap_or(rest);
    let rest = rest.strip_prefix("fn ")?;
    let end = rest.find(|c: char| !(c.is_alphanumeric() || c == '_'))?;
    Some(&rest[..end])
}

/// Whether the attribute and comment lines just above line `k` say how the
/// function is compiled.
fn says_how(lines: &[(usize, &str)], k: usize) -> bool {
    lines[..k]
        .iter()
        .rev()
        .map(|(_, l)| l.trim_start())
        .take_while(|l| l.starts_with("#[") || l.starts_with("//"))
        .any(|l| l.starts_with("#[inline(always)]") || l.starts_with("#[inline(never)]"))
}

/// The methods called as `self.name(`.
fn self_calls(line: &str) -> Vec<&str> {
    let mut calls = Vec::new();
    let mut rest = line;
    while let Some(at) = rest.find("self.") {
        let after = &rest[at + 5..];
        let end = after
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(after.len());
        if after[end..].starts_with('(') {
            calls.push(&after[..end]);
        }
        rest = &after[end..];
    }
    calls
}

#[test]
fn every_step_function_says_how_it_is_inlined() {
    let mut defined = Vec::new();
    let mut unmarked = Vec::new();
    for (path, source, start) in STEP_FILES {
        let lines = step_lines(source, start);
        for (k, (number, line)) in lines.iter().enumerate() {
            if let Some(name) = declared_fn(line) {
                defined.push(name);
                if !says_how(&lines, k) {
                    unmarked.push(format!("{path}:{number} fn {name}"));
                }
            }
        }
    }
    assert!(defined.len() > 40, "found only {} functions", defined.len());
    assert!(
        unmarked.is_empty(),
        "step functions without #[inline(always)] or #[inline(never)] (the AVX2 \
         rule, src/plant/step.rs):\n{}",
        unmarked.join("\n")
    );

    let mut outside_calls = Vec::new();
    let mut outside_fns = Vec::new();
    for (path, source, start) in STEP_FILES {
        let lines = step_lines(source, start);
        for (number, line) in &lines {
            for name in self_calls(line) {
                if !defined.contains(&name) {
                    outside_calls.push(format!("{path}:{number} self.{name}(..)"));
                }
            }
        }
        // `use` statements, joined over their lines.
        let text = lines.iter().map(|(_, l)| *l).collect::<Vec<_>>().join("\n");
        for statement in text.split(';').map(str::trim) {
            let Some(used) = statement.strip_prefix("use ") else {
                continue;
            };
            let Some(module) = OUTSIDE.iter().find(|m| used.starts_with(*m)) else {
                continue;
            };
            let names = used[module.len()..].trim_matches(|c: char| c == '{' || c == '}');
            for name in names.split(',').map(str::trim).filter(|n| !n.is_empty()) {
                let leaf = name.rsplit("::").next().unwrap_or(name);
                if !leaf.starts_with(|c: char| c.is_ascii_uppercase()) {
                    outside_fns.push(format!("{path}: use {module}{name}"));
                }
            }
        }
    }
    assert!(
        outside_calls.is_empty(),
        "the step calls methods defined outside the step modules (move them \
         into one, with #[inline(always)]):\n{}",
        outside_calls.join("\n")
    );
    assert!(
        outside_fns.is_empty(),
        "the step modules import functions from outside them:\n{}",
        outside_fns.join("\n")
    );
}

/// The checker itself finds what it is for.
#[test]
fn the_checker_finds_an_unmarked_function_and_an_outside_call() {
    let source = "/// doc\n#[inline(always)]\nfn good() {}\n\n/// doc\npub(crate) fn bad(x: f64) {\n    self.helper(x);\n}\n#[cfg(test)]\nfn tested() {}\n";
    let lines = step_lines(source, None);
    let found: Vec<_> = lines
        .iter()
        .enumerate()
        .filter_map(|(k, (_, l))| declared_fn(l).map(|n| (n, says_how(&lines, k))))
        .collect();
    assert_eq!(found, [("good", true), ("bad", false)]);
    assert_eq!(
        self_calls("let a = self.x.y(self.helper(1), self.field);"),
        ["helper"]
    );
}
