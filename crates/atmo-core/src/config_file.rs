//! The one loading layer of every config file of the project.
//!
//! A config type is declared with [`crate::params!`] (each parameter once:
//! doc, type, default, range, unit; strict `Deserialize` included) and
//! implements [`ConfigFile::validate`], usually as
//! [`crate::params::check_file`]; it then gets [`ConfigFile::load`] and
//! [`ConfigFile::from_toml_str`]. Loading is strict: unknown keys, missing
//! keys and wrong types are refused by serde with the file, the line and the
//! full key path; every value is then checked against its range by a
//! [`Checker`], whose errors name the file, the key, what was expected (with
//! its unit) and what was found.
//!
//! Adding one parameter is one line of its table's `params!`, e.g.
//! `pub duration: f64, range 0.01..=10.0, unit "s";`, with a default when
//! files written before it exist (the default says what they meant).

use std::fmt::Display;
use std::ops::RangeInclusive;
use std::path::Path;

use nalgebra::Matrix3;
use serde::de::DeserializeOwned;

use crate::error::{CoreError, Result};
use crate::input_file;

/// A TOML config file: strictly parsed, then validated.
///
/// Each crate keeps its own error type: `Error` only has to accept the
/// [`CoreError`]s of reading and parsing (every crate's error has a
/// `#[from] CoreError` variant).
pub trait ConfigFile: DeserializeOwned {
    /// The error type of the crate that owns the config.
    type Error: From<CoreError>;

    /// Checks every value against its range; errors name `file` and the key.
    ///
    /// # Errors
    /// The first value out of range.
    fn validate(&self, file: &Path) -> std::result::Result<(), Self::Error>;

    /// Runs once after parsing and before [`ConfigFile::validate`], with the
    /// file's path: resolve paths relative to it, or remember it. Default:
    /// nothing.
    fn locate(&mut self, _file: &Path) {}

    /// Parses and validates `text`; `file` names the origin in errors.
    ///
    /// # Errors
    /// Bad TOML, unknown, missing or mistyped keys (with file, line and key
    /// path), and any value [`ConfigFile::validate`] refuses.
    fn from_toml_str(text: &str, file: impl AsRef<Path>) -> std::result::Result<Self, Self::Error> {
        let file = file.as_ref();
        let mut config: Self = parse_toml(text, file)?;
        config.locate(file);
        config.validate(file)?;
        Ok(config)
    }

    /// Reads, parses and validates the file at `path`.
    ///
    /// # Errors
    /// As [`ConfigFile::from_toml_str`], and a file that cannot be read.
    fn load(path: impl AsRef<Path>) -> std::result::Result<Self, Self::Error> {
        let path = path.as_ref();
        Self::from_toml_str(&read_config_file(path)?, path)
    }
}

/// Parses a TOML document of type `T` strictly, with errors that name `file`,
/// the line and the full key path.
///
/// # Errors
/// [`CoreError::ConfigParse`].
pub fn parse_toml<T: DeserializeOwned>(text: &str, file: &Path) -> Result<T> {
    let deserializer = toml::Deserializer::new(text);
    let parsed: T = serde_path_to_error::deserialize(deserializer).map_err(|err| {
        let key = err.path().to_string();
        let inner = err.into_inner();
        let line = inner.span().map_or(0, |span| {
            text[..span.start.min(text.len())].matches('\n').count() + 1
        });
        CoreError::ConfigParse {
            file: file.to_path_buf(),
            line,
            key: if key == "." {
                // The TOML parser's own errors (a number that does not fit,
                // bad syntax) come without a path: the line's key says it.
                key_at_line(text, line).unwrap_or_else(|| "(document)".into())
            } else {
                key
            },
            message: inner.message().to_string(),
        }
    })?;
    check_shape::<T>(text, file)?;
    Ok(parsed)
}

/// The dotted key whose value is on 1-based `line` of a TOML `text`: the
/// table header above it (`[log]`, `[[pilot]]`) and the key left of its
/// `=`, on that line or, for a value that spans lines (an array or an
/// inline table left open, `x = [1, 2` up to the end of the file), on the
/// line that opened it.
fn key_at_line(text: &str, line: usize) -> Option<String> {
    let mut table = String::new();
    // The key whose array or inline table is still open, and how deep.
    let mut open: Option<(String, i64)> = None;
    for (i, l) in text.lines().enumerate().take(line) {
        let l = l.trim();
        let on_error_line = i + 1 == line;
        if let Some((key, depth)) = open.as_mut() {
            if on_error_line {
                return Some(key.clone());
            }
            *depth += bracket_depth(l);
            if *depth <= 0 {
                open = None;
            }
            continue;
        }
        if l.starts_with('[') {
            let header = l.trim_start_matches('[');
            table = header.split(']').next().unwrap_or("").trim().to_string();
            continue;
        }
        let Some((key, value)) = l.split_once('=') else {
            continue;
        };
        let key = key.trim();
        if key.is_empty() || key.starts_with('#') {
            continue;
        }
        let key = if table.is_empty() {
            key.to_string()
        } else {
            format!("{table}.{key}")
        };
        if on_error_line {
            return Some(key);
        }
        let depth = bracket_depth(value);
        if depth > 0 {
            open = Some((key, depth));
        }
    }
    // The error is past the last line (the end of the file): in the value
    // still open there, if any.
    open.map(|(key, _)| key)
}

/// How many more `[` / `{` than `]` / `}` a line of TOML opens, outside its
/// strings and its comment.
fn bracket_depth(line: &str) -> i64 {
    let mut depth = 0;
    let mut quote: Option<char> = None;
    let mut escaped = false;
    for c in line.chars() {
        match quote {
            Some(q) => {
                if escaped {
                    escaped = false;
                } else if c == '\\' && q == '"' {
                    escaped = true;
                } else if c == q {
                    quote = None;
                }
            }
            None => match c {
                '"' | '\'' => quote = Some(c),
                '#' => break,
                '[' | '{' => depth += 1,
                ']' | '}' => depth -= 1,
                _ => {}
            },
        }
    }
    depth
}

/// The document's shape, strictly: the document deserializer above leaves
/// the elements of an array past a fixed-size field's length unread
/// (`yaw_sign = [1, 1, -1, -1, 1, "x"]` reads as its first four), so
/// the same document is read a second time as a [`toml::Table`], whose
/// deserializer refuses any element left over. The error names the key
/// path and the line of its last segment.
fn check_shape<T: DeserializeOwned>(text: &str, file: &Path) -> Result<()> {
    let Ok(table) = text.parse::<toml::Table>() else {
        return Ok(()); // the document parsed above; nothing more to learn
    };
    let Err(err) = serde_path_to_error::deserialize::<_, T>(toml::Value::Table(table)) else {
        return Ok(());
    };
    let key = err.path().to_string();
    let last = key
        .rsplit('.')
        .next()
        .unwrap_or("")
        .split('[')
        .next()
        .unwrap_or("")
        .to_string();
    let line = text
        .lines()
        .position(|l| {
            let l = l.trim_start();
            !last.is_empty()
                && l.strip_prefix(last.as_str())
                    .is_some_and(|rest| rest.trim_start().starts_with('='))
        })
        .map_or(0, |i| i + 1);
    let message = err.into_inner().message().to_string();
    Err(CoreError::ConfigParse {
        file: file.to_path_buf(),
        line,
        key: if key == "." { "(document)".into() } else { key },
        message: if message.contains("fewer elements in array") {
            format!(
                "more elements than the key takes ({}): a fixed-size array takes exactly its size",
                message.split(',').next().unwrap_or(&message)
            )
        } else {
            message
        },
    })
}

/// Reads a whole file for a config loader, naming it on failure: a
/// regular file of UTF-8 text within [`input_file::CONFIGURATION`]'s limit.
///
/// # Errors
/// [`CoreError::ConfigRead`].
pub fn read_config_file(path: &Path) -> Result<String> {
    input_file::read_text(path, input_file::CONFIGURATION).map_err(|cause| CoreError::ConfigRead {
        file: path.to_path_buf(),
        cause,
    })
}

/// A number that `f64`'s `Display` writes out in hundreds of digits
/// (`1e300`, `1e-300`) in exponent form; anything else as it is.
fn readable_number(text: String) -> String {
    // An integer of up to 128 bits has at most 40 characters.
    if text.len() > 40
        && let Ok(value) = text.parse::<f64>()
    {
        return format!("{value:e}");
    }
    text
}

/// Serde default of a switch that is on unless the file says otherwise
/// (`#[serde(default = "atmo_core::config_file::default_true")]`).
pub fn default_true() -> bool {
    true
}

/// A number a [`Checker::range`] can bound: floats must also be finite.
pub trait Bounded: PartialOrd + Display + Copy {
    /// How the expected value is described: "a value" or "an integer".
    const KIND: &'static str;
    fn is_number(self) -> bool;
}

impl Bounded for f64 {
    const KIND: &'static str = "a value";
    fn is_number(self) -> bool {
        self.is_finite()
    }
}

macro_rules! bounded_integer {
    ($($t:ty),*) => {$(
        impl Bounded for $t {
            const KIND: &'static str = "an integer";
            fn is_number(self) -> bool {
                true
            }
        }
    )*};
}
bounded_integer!(u32, u64, usize, i64);

/// Collects value checks for one file so that each failure names its key.
pub struct Checker<'a> {
    file: &'a Path,
}

impl<'a> Checker<'a> {
    pub fn new(file: &'a Path) -> Self {
        Self { file }
    }

    /// The error for `key`: expected `expected`, got `got`.
    pub fn fail(
        &self,
        key: &str,
        expected: impl Into<String>,
        got: impl std::fmt::Display,
    ) -> CoreError {
        CoreError::ConfigValue {
            file: self.file.to_path_buf(),
            key: key.to_string(),
            expected: expected.into(),
            got: readable_number(got.to_string()),
        }
    }

    /// `value` must lie in `range` (and be finite); `unit` (`"kg"`, `"ms"`,
    /// `""` for none) is named in the error.
    ///
    /// # Errors
    /// [`CoreError::ConfigValue`] naming `key`.
    pub fn range<T: Bounded>(
        &self,
        key: &str,
        value: T,
        range: RangeInclusive<T>,
        unit: &str,
    ) -> Result<()> {
        if value.is_number() && range.contains(&value) {
            return Ok(());
        }
        let unit = if unit.is_empty() {
            String::new()
        } else {
            format!(" {unit}")
        };
        let (min, max) = range.into_inner();
        Err(self.fail(key, format!("{} in [{min}, {max}]{unit}", T::KIND), value))
    }

    /// `value` must be finite and within `[min, max]`.
    ///
    /// # Errors
    /// [`CoreError::ConfigValue`] naming `key`.
    pub fn within(&self, key: &str, value: f64, min: f64, max: f64) -> Result<()> {
        self.range(key, value, min..=max, "")
    }

    /// Every entry must be finite.
    ///
    /// # Errors
    /// [`CoreError::ConfigValue`] naming `key`.
    pub fn finite(&self, key: &str, values: &[f64]) -> Result<()> {
        match values.iter().find(|v| !v.is_finite()) {
            None => Ok(()),
            Some(v) => Err(self.fail(key, "finite numbers", v)),
        }
    }

    /// `value` must be one of `allowed`.
    ///
    /// # Errors
    /// [`CoreError::ConfigValue`] naming `key` and listing `allowed`.
    pub fn one_of(&self, key: &str, value: &str, allowed: &[&str]) -> Result<()> {
        if allowed.contains(&value) {
            Ok(())
        } else {
            let list: Vec<String> = allowed.iter().map(|a| format!("`{a}`")).collect();
            Err(self.fail(key, format!("one of {}", list.join(", ")), value))
        }
    }

    /// The tensor must be symmetric positive definite and satisfy the
    /// triangle inequalities of a physical body (principal moments).
    ///
    /// # Errors
    /// [`CoreError::ConfigValue`] naming `key`.
    pub fn inertia(&self, key: &str, inertia: &Matrix3<f64>) -> Result<()> {
        self.finite(key, inertia.as_slice())?;
        let eig = inertia.symmetric_eigenvalues();
        let (a, b, c) = (eig[0], eig[1], eig[2]);
        if a <= 0.0 || b <= 0.0 || c <= 0.0 {
            return Err(self.fail(
                key,
                "a positive-definite inertia tensor",
                format!("principal moments ({a:.3e}, {b:.3e}, {c:.3e})"),
            ));
        }
        let tol = 1e-12 * (a + b + c);
        if a + b + tol < c || a + c + tol < b || b + c + tol < a {
            return Err(self.fail(
                key,
                "principal moments that satisfy the triangle inequality",
                format!("({a:.3e}, {b:.3e}, {c:.3e})"),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_parser_error_without_a_path_names_the_key_of_its_line() {
        #[derive(Debug, serde::Deserialize)]
        #[allow(dead_code)] // reason: only parsed
        struct Log {
            queue: u64,
        }
        #[derive(Debug, serde::Deserialize)]
        #[allow(dead_code)] // reason: only parsed
        struct File {
            name: String,
            log: Log,
        }
        let text = "name = \"x\"\n[log]  # the writer\nqueue = 18446744073709551615\n";
        let err = parse_toml::<File>(text, Path::new("d.toml")).unwrap_err();
        let msg = err.to_string();
        assert!(msg.starts_with("d.toml:3: key `log.queue`: "), "{msg}");
        // An empty document: no line with a key, the document is named.
        let msg = parse_toml::<File>("", Path::new("d.toml"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("key `(document)`: missing field"), "{msg}");
        // An array left open: the error is at the end of the file, the key
        // is the one that opened it ("key `(document)`" before).
        for text in [
            "name = \"x\"\n[log]\nqueue = [1,\n  2\n",
            "[log]\nqueue = [1, \"]\", # ]\n 2,\n",
        ] {
            let msg = parse_toml::<File>(text, Path::new("d.toml"))
                .unwrap_err()
                .to_string();
            assert!(msg.contains("key `log.queue`"), "{text:?}: {msg}");
        }
        // A line that is no key's value after a closed one names none.
        let msg = parse_toml::<File>("name = \"x\"\nlog\n", Path::new("d.toml"))
            .unwrap_err()
            .to_string();
        assert!(msg.starts_with("d.toml:2: key `(document)`"), "{msg}");
    }

    #[test]
    fn range_names_key_bounds_unit_and_value() {
        let c = Checker::new(Path::new("f.toml"));
        assert!(c.range("a.b", 5_u64, 1..=10, "ms").is_ok());
        let msg = c.range("a.b", 0_u64, 1..=10, "ms").unwrap_err().to_string();
        assert_eq!(
            msg,
            "f.toml: key `a.b`: expected an integer in [1, 10] ms, got 0"
        );
        let msg = c
            .range("x", f64::NAN, 0.0..=1.0, "")
            .unwrap_err()
            .to_string();
        assert_eq!(msg, "f.toml: key `x`: expected a value in [0, 1], got NaN");
        for (value, shown) in [(1e300, "1e300"), (-1e-300, "-1e-300"), (0.25, "0.25")] {
            let msg = c.range("x", value, 0.0..=0.2, "").unwrap_err().to_string();
            assert!(msg.ends_with(&format!("got {shown}")), "{msg}");
        }
        assert!(c.range("x", 1.0, 0.0..=1.0, "kg").is_ok());
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code, reason = "read by serde only")]
    struct Rotor {
        k_thrust: f64,
        yaw_sign: [f64; 4],
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code, reason = "read by serde only")]
    struct Robot {
        name: String,
        rotor: Rotor,
    }

    /// `yaw_sign` with 6 items, one a string, was accepted as its first
    /// four: an array of a fixed size takes exactly that many elements, and
    /// the error names the file, the line and the key.
    #[test]
    fn fixed_size_arrays_refuse_extra_or_mistyped_elements() {
        let doc =
            |signs: &str| format!("name = \"r\"\n\n[rotor]\nk_thrust = 10.0\nyaw_sign = {signs}\n");
        let ok: Robot = parse_toml(&doc("[1, 1, -1.0, -1]"), Path::new("r.toml")).unwrap();
        assert_eq!(ok.rotor.yaw_sign, [1.0, 1.0, -1.0, -1.0]);
        for signs in [
            "[1.0, 1.0, -1.0, -1.0, 1.0, \"x\"]",
            "[1.0, 1.0, -1.0, -1.0, 1.0]",
            "[1.0, 1.0, -1.0]",
            "[1.0, 1.0, -1.0, \"x\"]",
        ] {
            let err = parse_toml::<Robot>(&doc(signs), Path::new("r.toml"))
                .unwrap_err()
                .to_string();
            assert!(
                err.contains("r.toml:5") && err.contains("rotor.yaw_sign"),
                "{signs}: {err}"
            );
        }
    }

    #[test]
    fn one_of_lists_the_choices() {
        let c = Checker::new(Path::new("f.toml"));
        assert!(c.one_of("k", "lz4", &["zstd", "lz4"]).is_ok());
        let msg = c
            .one_of("k", "gzip", &["zstd", "lz4"])
            .unwrap_err()
            .to_string();
        assert!(msg.contains("one of `zstd`, `lz4`, got gzip"), "{msg}");
    }
}
