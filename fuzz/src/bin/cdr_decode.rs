//! Fuzz target `cdr_decode` (see the crate docs).

fn main() {
    atmo_fuzz::run(atmo_fuzz::cdr_decode);
}
