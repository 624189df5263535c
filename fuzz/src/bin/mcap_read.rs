//! Fuzz target `mcap_read` (see the crate docs).

fn main() {
    atmo_fuzz::run(atmo_fuzz::mcap_read);
}
