//! Fuzz target `config_toml` (see the crate docs).

fn main() {
    atmo_fuzz::run(atmo_fuzz::config_toml);
}
