//! Fuzz target `mcap_recover` (see the crate docs).

fn main() {
    atmo_fuzz::run(atmo_fuzz::mcap_recover);
}
