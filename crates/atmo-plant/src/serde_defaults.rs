//! serde defaults shared by the config types of several modules (config.rs
//! and ground_effect.rs), in a module of their own so that neither imports
//! the other for them.

/// serde default of every `enabled` key: a present section is on.
pub fn default_true() -> bool {
    true
}
