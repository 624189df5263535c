//! Fuzz target `recording_csv` (see the crate docs).

fn main() {
    atmo_fuzz::run(atmo_fuzz::recording_csv);
}
