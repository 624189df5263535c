//! Fuzz target `recording_csv` (see the atmo-fuzz crate docs).

fn main() {
    atmo_fuzz_afl::run(atmo_fuzz::recording_csv);
}
