//! The fuzz targets of `crates/atmo-fuzz` as cargo-afl binaries, one per
//! target (`src/bin/`), for coverage-guided campaigns (scripts/fuzz.sh,
//! docs/fuzzing.md).
//!
//! With the `afl` feature each binary runs AFL++'s persistent loop; without
//! it, it replays the files and folders named on its command line, for
//! reproducing a finding: `cargo run --bin mcap_read -- FILE...`.

#[cfg(not(feature = "afl"))]
use std::path::PathBuf;

/// Runs `target` under AFL++ (feature `afl`) or over the files named in the
/// arguments.
pub fn run(target: atmo_fuzz::Target) {
    #[cfg(feature = "afl")]
    afl::fuzz(true, target);
    #[cfg(not(feature = "afl"))]
    {
        let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
        let inputs = atmo_fuzz::corpus_files(&args);
        for file in &inputs {
            let data = std::fs::read(file)
                .unwrap_or_else(|e| panic!("cannot read {}: {e}", file.display()));
            eprintln!("{}", file.display());
            target(&data);
        }
        eprintln!("{} inputs, no crash", inputs.len());
    }
}
