//! Parameters declared once: the [`params!`](crate::params!) macro.
//!
//! A config table is declared as a struct whose every field says, in one
//! place, its doc, its type, its default (if it has one), its range and its
//! unit:
//!
//! ```
//! atmo_core::params! {
//!     /// A disturbance observer's gains.
//!     #[derive(Debug, Clone, PartialEq)]
//!     pub struct Observer {
//!         /// Per estimate.
//!         pub force_gain: f64, range 0.0..=1.0;
//!         /// Largest force per axis.
//!         pub max_force: f64 = 15.0, range 0.0..=200.0, unit "N";
//!         /// Smallest spacing of two differenced estimates (0: any; the
//!         /// behaviour of files written before the key).
//!         pub min_interval: f64 = 0.0, range 0.0..=0.05, unit "s";
//!     }
//! }
//! use atmo_core::params::Params as _;
//! let o: Observer = atmo_core::config_file::parse_toml(
//!     "force_gain = 0.02", std::path::Path::new("o.toml")).unwrap();
//! assert_eq!((o.max_force, o.min_interval), (15.0, 0.0));
//! let keys: Vec<String> = Observer::params().into_iter().map(|p| p.key).collect();
//! assert_eq!(keys, ["force_gain", "max_force", "min_interval"]);
//! ```
//!
//! The macro writes the struct (the docs on its fields), its `Deserialize`
//! (strict: an unknown or repeated key is an error, a key without a
//! default is required, a missing key with one takes it) and its
//! [`Params`]: [`Params::check`], every range checked with the full key
//! path and unit in the error, and [`Params::params`], the table of every
//! parameter for `--params` listings and the docs.
//!
//! Field forms, after `name: Type`:
//! - `= expr`: the default of a key a file may leave out. A key added to a
//!   file that was written without it must default to the behaviour before
//!   it, so that every older flight log still replays. Unlike serde's
//!   derive, an `Option` field is required unless declared `= None`.
//! - `key "loop"`: the key's name in the file when it is not the field's.
//! - `range a..=b` or `range Finite`: checked by
//!   [`CheckRange`]; an array or `Vec` checks each element (its index in
//!   the key), an `Option` its value when present. The bounds may name
//!   fields declared before (bound by reference: `range 0.0..=*max_speed`),
//!   whose own ranges are checked first.
//! - `unit "N"`: named in listings and in the range's error.
//!
//! A field whose type is itself a `params!` table (or an `Option` of one)
//! is a nested table: checked and listed under its key, with no marker.
//!
//! `pub struct Name: Default { ... }` also implements `Default` from the
//! declared defaults (every field must have one): a table a file may
//! leave out whole.
//!
//! Checks a range cannot say (one key against another, a physical
//! property of several) go in a trailing `check |table, c, prefix| expr`,
//! which sees the table, the [`Checker`], the key prefix and each field by
//! reference, and returns `Result<(), CoreError>`.
//!
//! A `Vec` of tables (`[[effects.wind.gusts]]`) is checked per element
//! (`gusts[1].duration`) and listed once (`gusts[].duration`).
//!
//! What a table cannot say, and how those types stay strict:
//! - a choice of words (`kind = "missed"`) is an enum with serde's derive
//!   and `rename_all`: unknown words are refused by serde, with the key
//!   path and line, and the field holding it is declared here;
//! - a field that is not read from the file (the plant's `source`, the
//!   scenario's resolved paths) keeps its struct on serde's derive with
//!   `deny_unknown_fields`; its tables are `params!` and its `validate`
//!   calls their [`Params::check`];
//! - keys shared by several tables (every actuator fault's onset `t`,
//!   `mode`, `delay`) are one `params!` table read beside the others by a
//!   small adapter (`atmo_sim::actuator_faults::Timed`), since the macro
//!   has no `flatten`;
//! - a bound that depends on another file (a fault's time within the
//!   scenario's duration) is checked by the owner that knows both.

use std::ops::RangeInclusive;

use crate::config_file::{Bounded, Checker};
use crate::error::Result;

/// One declared parameter, for listings and docs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamInfo {
    /// Full key path, e.g. `observer.max_force`.
    pub key: String,
    /// The Rust type, as written.
    pub ty: &'static str,
    /// The default as written, `None` for a required key.
    pub default: Option<&'static str>,
    /// The default of the enclosing table a file may leave out whole
    /// (the innermost such table), as written.
    pub table_default: Option<&'static str>,
    /// The range as written, `None` when unchecked.
    pub range: Option<&'static str>,
    pub unit: &'static str,
    pub doc: &'static str,
}

impl ParamInfo {
    /// The doc on one line.
    pub fn doc_line(&self) -> String {
        self.doc.split_whitespace().collect::<Vec<_>>().join(" ")
    }
}

/// `params` as a Markdown table under the heading `file`: key, default
/// (`required` when none), range, unit and doc, one line each.
pub fn markdown_table(file: &str, params: &[ParamInfo]) -> String {
    use std::fmt::Write as _;
    let mut out =
        format!("### {file}\n\n| key | default | range | unit | doc |\n|---|---|---|---|---|\n");
    let cell = |s: &str| s.replace('|', "\\|");
    for p in params {
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} |",
            p.key,
            match (p.default, p.table_default) {
                (Some(d), _) => format!("`{}`", cell(d)),
                (None, Some(t)) => format!("required in the table (absent table: `{}`)", cell(t)),
                (None, None) => "required".to_string(),
            },
            p.range.map_or(String::new(), |r| format!("`{}`", cell(r))),
            p.unit,
            cell(&p.doc_line()),
        );
    }
    out
}

/// A config table declared with [`params!`](crate::params!).
pub trait Params {
    /// Checks every declared range and the table's own checks; keys are
    /// named under `prefix` (`""` at the top of a file).
    ///
    /// # Errors
    /// The first value out of its range, naming its full key.
    fn check(&self, c: &Checker, prefix: &str) -> Result<()>;

    /// Appends this table's parameters, nested tables expanded, under
    /// `prefix`.
    fn list(prefix: &str, out: &mut Vec<ParamInfo>);

    /// Every parameter of the table, in declaration order.
    fn params() -> Vec<ParamInfo> {
        let mut out = Vec::new();
        Self::list("", &mut out);
        out
    }
}

impl<T: Params> Params for Option<T> {
    fn check(&self, c: &Checker, prefix: &str) -> Result<()> {
        self.as_ref().map_or(Ok(()), |t| t.check(c, prefix))
    }

    fn list(prefix: &str, out: &mut Vec<ParamInfo>) {
        T::list(prefix, out);
    }
}

/// Checks a whole file's table `config`; errors name `file` and the key:
/// the body of a [`crate::ConfigFile::validate`] of a `params!` type.
///
/// # Errors
/// The first value out of its range.
pub fn check_file<T: Params>(config: &T, file: &std::path::Path) -> Result<()> {
    config.check(&Checker::new(file), "")
}

/// A table of named tables (`[presets.fig5]`, `[presets.default]`): each
/// checked under its name, listed once under `<name>`.
impl<T: Params> Params for std::collections::BTreeMap<String, T> {
    fn check(&self, c: &Checker, prefix: &str) -> Result<()> {
        self.iter()
            .try_for_each(|(name, t)| t.check(c, &key(prefix, name)))
    }

    fn list(prefix: &str, out: &mut Vec<ParamInfo>) {
        T::list(&key(prefix, "<name>"), out);
    }
}

/// An array of tables (`[[effects.wind.gusts]]`): each checked under
/// `<key>[i]`, listed once under `<key>[]`.
impl<T: Params> Params for Vec<T> {
    fn check(&self, c: &Checker, prefix: &str) -> Result<()> {
        self.iter()
            .enumerate()
            .try_for_each(|(i, t)| t.check(c, &format!("{prefix}[{i}]")))
    }

    fn list(prefix: &str, out: &mut Vec<ParamInfo>) {
        T::list(&format!("{prefix}[]"), out);
    }
}

/// The full key of `name` under `prefix`.
pub fn key(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_string()
    } else {
        format!("{prefix}.{name}")
    }
}

/// What a declared `range` allows: `a..=b` or [`Finite`]. A quantity with
/// a physical scale declares its bounds; only a coordinate is `Finite`.
#[derive(Debug, Clone, PartialEq)]
pub enum Span<B> {
    Within(RangeInclusive<B>),
    /// Any finite number.
    Finite,
}

/// `range Finite`: any finite number.
#[derive(Debug, Clone, Copy)]
pub struct Finite;

impl<B> From<RangeInclusive<B>> for Span<B> {
    fn from(range: RangeInclusive<B>) -> Self {
        Self::Within(range)
    }
}

impl<B> From<Finite> for Span<B> {
    fn from(_: Finite) -> Self {
        Self::Finite
    }
}

impl<B: Bounded> Span<B> {
    /// # Errors
    /// `value` outside the span, naming `key`.
    pub fn check(&self, c: &Checker, key: &str, value: B, unit: &str) -> Result<()> {
        match self {
            Self::Within(range) => c.range(key, value, range.clone(), unit),
            Self::Finite if value.is_number() => Ok(()),
            Self::Finite => Err(c.fail(key, "a finite number", value)),
        }
    }
}

/// A value a declared `range` bounds.
pub trait CheckRange<B> {
    /// # Errors
    /// A value (or element) outside `span`, naming `key` (and its index).
    fn check_range(&self, c: &Checker, key: &str, span: Span<B>, unit: &str) -> Result<()>;
}

impl<B: Bounded> CheckRange<B> for B {
    fn check_range(&self, c: &Checker, key: &str, span: Span<B>, unit: &str) -> Result<()> {
        span.check(c, key, *self, unit)
    }
}

fn check_each<B: Bounded>(
    values: &[B],
    c: &Checker,
    key: &str,
    span: &Span<B>,
    unit: &str,
) -> Result<()> {
    for (i, v) in values.iter().enumerate() {
        span.check(c, &format!("{key}[{i}]"), *v, unit)?;
    }
    Ok(())
}

impl<B: Bounded, const N: usize> CheckRange<B> for [B; N] {
    fn check_range(&self, c: &Checker, key: &str, span: Span<B>, unit: &str) -> Result<()> {
        check_each(self, c, key, &span, unit)
    }
}

impl<B: Bounded> CheckRange<B> for Vec<B> {
    fn check_range(&self, c: &Checker, key: &str, span: Span<B>, unit: &str) -> Result<()> {
        check_each(self, c, key, &span, unit)
    }
}

impl<B, T: CheckRange<B>> CheckRange<B> for Option<T> {
    fn check_range(&self, c: &Checker, key: &str, span: Span<B>, unit: &str) -> Result<()> {
        self.as_ref()
            .map_or(Ok(()), |v| v.check_range(c, key, span, unit))
    }
}

/// Reads a key of a table with the keys `.0`: an unknown key fails while
/// it is read, so that its error names the key's full path (as serde's
/// derived `deny_unknown_fields` does).
#[doc(hidden)]
pub struct KeyOf(pub &'static [&'static str]);

impl<'de> serde::de::DeserializeSeed<'de> for KeyOf {
    type Value = &'static str;

    fn deserialize<D: serde::Deserializer<'de>>(
        self,
        deserializer: D,
    ) -> std::result::Result<&'static str, D::Error> {
        deserializer.deserialize_identifier(self)
    }
}

impl serde::de::Visitor<'_> for KeyOf {
    type Value = &'static str;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a key")
    }

    fn visit_str<E: serde::de::Error>(self, key: &str) -> std::result::Result<&'static str, E> {
        self.0
            .iter()
            .find(|k| **k == key)
            .copied()
            .ok_or_else(|| E::unknown_field(key, self.0))
    }
}

/// A field's value, for the macro's choice between a nested table (its
/// [`Params`] are checked) and a value: a field whose type is a table is
/// checked without being marked, so none can be forgotten.
#[doc(hidden)]
pub struct Field<'a, T>(pub &'a T);

/// A field's type, for the same choice when listing.
#[doc(hidden)]
pub struct Kind<T>(pub std::marker::PhantomData<T>);

/// Chosen for a field whose type is a table (method resolution takes the
/// impl on `Field` before the one on `&Field`).
#[doc(hidden)]
pub trait NestedField {
    /// # Errors
    /// The nested table's first value out of range.
    fn check_nested(&self, c: &Checker, key: &str) -> Result<()>;
    fn list_nested(&self, info: ParamInfo, out: &mut Vec<ParamInfo>);
}

impl<T: Params> NestedField for Field<'_, T> {
    fn check_nested(&self, c: &Checker, key: &str) -> Result<()> {
        self.0.check(c, key)
    }
    fn list_nested(&self, info: ParamInfo, out: &mut Vec<ParamInfo>) {
        list_table::<T>(&info, out);
    }
}

impl<T: Params> NestedField for Kind<T> {
    fn check_nested(&self, _: &Checker, _: &str) -> Result<()> {
        Ok(())
    }
    fn list_nested(&self, info: ParamInfo, out: &mut Vec<ParamInfo>) {
        list_table::<T>(&info, out);
    }
}

/// Lists the nested table `table` declares; its default (if any) is the
/// table default of its keys.
fn list_table<T: Params>(table: &ParamInfo, out: &mut Vec<ParamInfo>) {
    let first = out.len();
    T::list(&table.key, out);
    if table.default.is_some() {
        for p in &mut out[first..] {
            p.table_default = p.table_default.or(table.default);
        }
    }
}

/// Chosen for every other field: a value, listed as itself.
#[doc(hidden)]
pub trait LeafField {
    /// # Errors
    /// None: a value without a declared range is not checked.
    fn check_nested(&self, _: &Checker, _: &str) -> Result<()> {
        Ok(())
    }
    fn list_nested(&self, info: ParamInfo, out: &mut Vec<ParamInfo>) {
        out.push(info);
    }
}

impl<T> LeafField for &Field<'_, T> {}
impl<T> LeafField for &Kind<T> {}

/// Declares a config table once; see the [module docs](mod@crate::params).
#[macro_export]
macro_rules! params {
    (
        $(#[$meta:meta])*
        $svis:vis struct $name:ident $(: $derive_default:ident)? {
            $(
                $(#[doc = $doc:literal])*
                $vis:vis $field:ident : $ty:ty
                $(= $default:expr)?
                $(, key $key:literal)?
                $(, range $range:expr)?
                $(, unit $unit:literal)?
                ;
            )*
        }
        $(check |$s:ident, $c:ident, $p:ident| $body:expr)?
    ) => {
        $(#[$meta])*
        $svis struct $name {
            $( $(#[doc = $doc])* $vis $field: $ty, )*
        }

        $crate::__param_default_impl!(
            [$($derive_default)?] $name [$($field [$($default)?]),*]
        );

        impl<'de> $crate::params::__serde::Deserialize<'de> for $name {
            fn deserialize<D>(deserializer: D) -> ::std::result::Result<Self, D::Error>
            where
                D: $crate::params::__serde::Deserializer<'de>,
            {
                use $crate::params::__serde::de;
                const FIELDS: &[&str] = &[$($crate::__param_key!($field $($key)?)),*];
                struct Visitor;
                impl<'de> de::Visitor<'de> for Visitor {
                    type Value = $name;
                    fn expecting(&self, f: &mut ::std::fmt::Formatter) -> ::std::fmt::Result {
                        f.write_str(concat!("a table of ", stringify!($name)))
                    }
                    fn visit_map<A: de::MapAccess<'de>>(
                        self,
                        mut map: A,
                    ) -> ::std::result::Result<$name, A::Error> {
                        $( let mut $field: ::std::option::Option<$ty> = None; )*
                        while let Some(name) = map.next_key_seed($crate::params::KeyOf(FIELDS))? {
                            $(
                                if name == $crate::__param_key!($field $($key)?) {
                                    if $field.is_some() {
                                        return Err(de::Error::duplicate_field(
                                            $crate::__param_key!($field $($key)?),
                                        ));
                                    }
                                    $field = Some(map.next_value()?);
                                    continue;
                                }
                            )*
                        }
                        Ok($name {
                            $(
                                $field: match $field {
                                    Some(value) => value,
                                    None => $crate::__param_default!(
                                        $crate::__param_key!($field $($key)?) $(, $default)?
                                    ),
                                },
                            )*
                        })
                    }
                }
                deserializer.deserialize_struct(stringify!($name), FIELDS, Visitor)
            }
        }

        impl $crate::params::Params for $name {
            #[allow(unused_variables, reason = "bounds and checks name only some fields")]
            fn check(
                &self,
                checker: &$crate::config_file::Checker,
                prefix: &str,
            ) -> $crate::Result<()> {
                let $name { $($field),* } = self;
                $(
                    $crate::__param_check!(
                        checker,
                        $crate::params::key(prefix, $crate::__param_key!($field $($key)?)),
                        $field,
                        [$($range)?],
                        [$($unit)?]
                    );
                )*
                $(
                    let $s = self;
                    let $c = checker;
                    let $p = prefix;
                    let extra: $crate::Result<()> = $body;
                    extra?;
                )?
                Ok(())
            }

            fn list(prefix: &str, out: &mut ::std::vec::Vec<$crate::params::ParamInfo>) {
                $(
                    $crate::__param_list!(
                        out,
                        $crate::params::key(prefix, $crate::__param_key!($field $($key)?)),
                        $ty,
                        concat!("" $(, $doc, "\n")*),
                        [$(stringify!($default))?],
                        [$(stringify!($range))?],
                        [$($unit)?]
                    );
                )*
            }
        }
    };
}

#[doc(hidden)]
pub use serde as __serde;

#[doc(hidden)]
#[macro_export]
macro_rules! __param_key {
    ($field:ident) => {
        stringify!($field)
    };
    ($field:ident $key:literal) => {
        $key
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __param_default {
    ($key:expr) => {
        return Err($crate::params::__serde::de::Error::missing_field($key))
    };
    ($key:expr, $default:expr) => {
        $default
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __param_default_impl {
    ([] $name:ident [$($field:ident [$($default:expr)?]),*]) => {};
    ([Default] $name:ident [$($field:ident [$default:expr]),*]) => {
        impl Default for $name {
            fn default() -> Self {
                Self { $($field: $default),* }
            }
        }
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __param_check {
    ($c:ident, $key:expr, $field:ident, [], [$($unit:literal)?]) => {{
        #[allow(unused_imports, reason = "one of the two is chosen")]
        use $crate::params::{LeafField as _, NestedField as _};
        (&$crate::params::Field($field)).check_nested($c, &$key)?
    }};
    ($c:ident, $key:expr, $field:ident, [$range:expr], [$($unit:literal)?]) => {
        {
            #[allow(unused_imports, reason = "for ranges that name them")]
            use $crate::params::Finite;
            $crate::params::CheckRange::check_range(
                $field,
                $c,
                &$key,
                ($range).into(),
                concat!("" $(, $unit)?),
            )?
        }
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __param_list {
    ($out:ident, $key:expr, $ty:ty, $doc:expr, [$($default:expr)?], [$($range:expr)?], [$($unit:literal)?]) => {{
        #[allow(unused_imports, reason = "one of the two is chosen")]
        use $crate::params::{LeafField as _, NestedField as _};
        let info = $crate::params::ParamInfo {
            key: $key,
            ty: stringify!($ty),
            default: $crate::__param_opt!($($default)?),
            table_default: None,
            range: $crate::__param_opt!($($range)?),
            unit: concat!("" $(, $unit)?),
            doc: $doc,
        };
        (&$crate::params::Kind::<$ty>(::std::marker::PhantomData)).list_nested(info, $out)
    }};
}

#[doc(hidden)]
#[macro_export]
macro_rules! __param_opt {
    () => {
        None
    };
    ($e:expr) => {
        Some($e)
    };
}

#[cfg(test)]
#[path = "params_tests.rs"]
mod tests;
