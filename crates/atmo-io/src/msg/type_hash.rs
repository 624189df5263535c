//! ROS 2 type hashes (`RIHS01_<sha256>`, REP-2011), from the `.msg` texts.
//!
//! ROS 2 (Iron and later) hashes a message type's *type description*: its
//! fields (name, type id, array capacity, string bound, nested type name)
//! and those of every type it references, transitively, sorted by name.
//! Constants, comments and default values are not part of it. The hash is
//! the SHA-256 of that description as JSON exactly as
//! `rosidl_generator_type_description` writes it (Python's `json.dumps`
//! with `", "` and `": "` separators, keys in the order below), in hex
//! after `RIHS01_`. An rmw announces it in each endpoint's USER_DATA
//! (`typehash=RIHS01_...;`), which RustDDS 0.15 cannot send (see the
//! README's ROS 2 section): the node publishes the hashes of its types on
//! `/diagnostics` instead, and tests compare them with rclpy's.

use std::fmt::Write as _;

use sha2::{Digest, Sha256};

use super::definitions::{ArrayKind, FieldDecl, definition, fields};
use crate::error::{IoError, Result};

/// `type_description_interfaces/msg/FieldType` ids of the primitives.
fn primitive_type_id(base: &str) -> Option<u8> {
    Some(match base {
        "int8" => 2,
        // `char` is an alias of uint8 in ROS 2 `.msg` files.
        "uint8" | "char" => 3,
        "int16" => 4,
        "uint16" => 5,
        "int32" => 6,
        "uint32" => 7,
        "int64" => 8,
        "uint64" => 9,
        "float32" => 10,
        "float64" => 11,
        "bool" => 15,
        "byte" => 16,
        "string" => 17,
        "wstring" => 18,
        _ => return None,
    })
}

const NESTED_TYPE: u8 = 1;
const BOUNDED_STRING: u8 = 21;
const BOUNDED_WSTRING: u8 = 22;
/// Added to the element's id: fixed array, bounded sequence, sequence.
const FIXED_ARRAY: u8 = 48;
const BOUNDED_SEQUENCE: u8 = 96;
const UNBOUNDED_SEQUENCE: u8 = 144;

/// `pkg/msg/Type` from `pkg/msg/Type` or `pkg/Type`.
fn full_name(type_name: &str) -> String {
    match type_name.split('/').collect::<Vec<_>>().as_slice() {
        [pkg, name] => format!("{pkg}/msg/{name}"),
        _ => type_name.to_string(),
    }
}

/// One type's `{"type_name": ..., "fields": [...]}` and the nested types
/// it names.
fn individual_description(type_name: &str) -> Result<(String, Vec<String>)> {
    let text = definition(type_name).ok_or_else(|| IoError::UnknownType {
        type_name: type_name.to_string(),
        field_type: type_name.to_string(),
    })?;
    let package = type_name.split('/').next().unwrap_or_default();
    let mut json = format!("{{\"type_name\": \"{type_name}\", \"fields\": [");
    let mut nested = Vec::new();
    let mut decls = fields(package, text);
    if decls.is_empty() {
        // rosidl gives an empty message a placeholder member.
        decls.push(FieldDecl {
            name: "structure_needs_at_least_one_member".into(),
            base: "uint8".into(),
            string_bound: None,
            array: ArrayKind::None,
        });
    }
    for (i, f) in decls.iter().enumerate() {
        let (element, nested_name) = match primitive_type_id(&f.base) {
            Some(17) if f.string_bound.is_some() => (BOUNDED_STRING, String::new()),
            Some(18) if f.string_bound.is_some() => (BOUNDED_WSTRING, String::new()),
            Some(id) => (id, String::new()),
            None => {
                let name = full_name(&f.base);
                if !nested.contains(&name) {
                    nested.push(name.clone());
                }
                (NESTED_TYPE, name)
            }
        };
        let (type_id, capacity) = match f.array {
            ArrayKind::None => (element, 0),
            ArrayKind::Fixed(n) => (element + FIXED_ARRAY, n),
            ArrayKind::Bounded(n) => (element + BOUNDED_SEQUENCE, n),
            ArrayKind::Unbounded => (element + UNBOUNDED_SEQUENCE, 0),
        };
        if i > 0 {
            json.push_str(", ");
        }
        let _ = write!(
            json,
            "{{\"name\": \"{}\", \"type\": {{\"type_id\": {type_id}, \"capacity\": {capacity}, \
             \"string_capacity\": {}, \"nested_type_name\": \"{nested_name}\"}}}}",
            f.name,
            f.string_bound.unwrap_or(0),
        );
    }
    json.push_str("]}");
    Ok((json, nested))
}

/// The JSON that is hashed: the type's description and every type it
/// references (transitively, each once, sorted by name).
pub fn hashed_description(type_name: &str) -> Result<String> {
    let root = full_name(type_name);
    let (root_json, mut queue) = individual_description(&root)?;
    let mut referenced: Vec<(String, String)> = Vec::new();
    while let Some(name) = queue.pop() {
        if name == root || referenced.iter().any(|(n, _)| *n == name) {
            continue;
        }
        let (json, nested) = individual_description(&name)?;
        referenced.push((name, json));
        queue.extend(nested);
    }
    referenced.sort();
    let refs: Vec<&str> = referenced.iter().map(|(_, j)| j.as_str()).collect();
    Ok(format!(
        "{{\"type_description\": {root_json}, \"referenced_type_descriptions\": [{}]}}",
        refs.join(", ")
    ))
}

/// The RIHS01 type hash of `type_name` (`pkg/msg/Type`), as rclpy and the
/// rmw layers compute it.
pub fn type_hash(type_name: &str) -> Result<String> {
    let digest = Sha256::digest(hashed_description(type_name)?.as_bytes());
    let mut out = String::from("RIHS01_");
    for byte in digest {
        let _ = write!(out, "{byte:02x}");
    }
    Ok(out)
}
