//! Fuzz target `mcap_recover` (see the atmo-fuzz crate docs).

fn main() {
    atmo_fuzz_afl::run(atmo_fuzz::mcap_recover);
}
