//! Root package of the ATMO workspace. It holds no code of its own: it owns the
//! cross-crate closed-loop tests in `tests/` and the benchmarks in `benches/`.
