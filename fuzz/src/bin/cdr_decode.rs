//! Fuzz target `cdr_decode` (see the atmo-fuzz crate docs).

fn main() {
    atmo_fuzz_afl::run(atmo_fuzz::cdr_decode);
}
