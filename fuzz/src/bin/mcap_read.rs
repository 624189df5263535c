//! Fuzz target `mcap_read` (see the atmo-fuzz crate docs).

fn main() {
    atmo_fuzz_afl::run(atmo_fuzz::mcap_read);
}
