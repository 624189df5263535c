//! Fuzz target `config_toml` (see the atmo-fuzz crate docs).

fn main() {
    atmo_fuzz_afl::run(atmo_fuzz::config_toml);
}
