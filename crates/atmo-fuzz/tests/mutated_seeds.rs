//! Every fuzz target on a bounded number of mutated copies of its committed
//! seeds, inside `cargo test` (the CI fuzz step, docs/fuzzing.md).
//!
//! No coverage guidance (that is the cargo-afl campaign's job, fuzz/): each
//! case takes one seed and applies 1 to 8 AFL-style havoc mutations (bit
//! flips, bytes set to boundary values, integers of 2, 4 or 8 bytes set to
//! boundary values, blocks deleted, inserted or copied, dictionary tokens
//! such as `nan` or `1e308` inserted). A panic or a failed check of a target
//! fails the test after proptest has shrunk the mutations to the fewest that
//! still fail; the failing input is written to
//! `target/tmp/fuzz-failures/<target>.bin` for `fuzz/`'s replay binaries.
//! An abort (out of memory) kills the test binary instead, unshrunk.
//!
//! `ATMO_FUZZ_CASES` sets the cases per target (by default those of the
//! tests below: about 2 s of one core each, docs/fuzzing.md);
//! `ATMO_FUZZ_SEED` (default 0) the random seed: the default run is the same
//! every time, another seed explores other mutations.
#![allow(clippy::unwrap_used, reason = "test")]

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestError, TestRng, TestRunner};

/// Integers at the edges of what parsers check: lengths, counts, sizes.
const BOUNDARY: [u64; 12] = [
    0,
    1,
    0x7f,
    0x80,
    0xff,
    0x7fff,
    0xffff,
    0x7fff_ffff,
    0xffff_ffff,
    1 << 56,
    i64::MAX as u64,
    u64::MAX,
];

/// Tokens inserted whole: the numbers and syntax the text parsers must
/// refuse or bound, and the MCAP magic.
const TOKENS: [&[u8]; 16] = [
    b"nan",
    b"inf",
    b"-inf",
    b"1e308",
    b"1e20",
    b"-1",
    b"0",
    b"1.7e12",
    b",",
    b"\n",
    b"=",
    b"[",
    b"\"",
    b"#",
    b"0x",
    b"\x89MCAP0\r\n",
];

/// One mutation; positions are taken modulo the input's length.
#[derive(Debug, Clone)]
enum Mutation {
    FlipBit {
        at: usize,
        bit: u8,
    },
    SetByte {
        at: usize,
        value: u8,
    },
    SetInt {
        at: usize,
        value: usize,
        width: usize,
    },
    Delete {
        at: usize,
        len: usize,
    },
    Insert {
        at: usize,
        bytes: Vec<u8>,
    },
    Token {
        at: usize,
        token: usize,
    },
    Copy {
        from: usize,
        to: usize,
        len: usize,
    },
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let at = any::<usize>();
    prop_oneof![
        (at, 0..8u8).prop_map(|(at, bit)| Mutation::FlipBit { at, bit }),
        (at, any::<u8>()).prop_map(|(at, value)| Mutation::SetByte { at, value }),
        (at, 0..BOUNDARY.len(), prop::sample::select(vec![2, 4, 8]))
            .prop_map(|(at, value, width)| Mutation::SetInt { at, value, width }),
        (at, 1..64usize).prop_map(|(at, len)| Mutation::Delete { at, len }),
        (at, prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(at, bytes)| Mutation::Insert { at, bytes }),
        (at, 0..TOKENS.len()).prop_map(|(at, token)| Mutation::Token { at, token }),
        (at, at, 1..256usize).prop_map(|(from, to, len)| Mutation::Copy { from, to, len }),
    ]
}

fn apply(input: &mut Vec<u8>, mutation: &Mutation) {
    let n = input.len();
    let pos = |at: usize| if n == 0 { 0 } else { at % n };
    match *mutation {
        Mutation::FlipBit { at, bit } if n > 0 => input[pos(at)] ^= 1 << bit,
        Mutation::SetByte { at, value } if n > 0 => input[pos(at)] = value,
        Mutation::SetInt { at, value, width } if n >= width => {
            let at = at % (n - width + 1);
            input[at..at + width].copy_from_slice(&BOUNDARY[value].to_le_bytes()[..width]);
        }
        Mutation::Delete { at, len } if n > 0 => {
            let at = pos(at);
            input.drain(at..(at + len).min(n));
        }
        Mutation::Insert { at, ref bytes } => {
            let at = pos(at);
            input.splice(at..at, bytes.iter().copied());
        }
        Mutation::Token { at, token } => {
            let at = pos(at);
            input.splice(at..at, TOKENS[token].iter().copied());
        }
        Mutation::Copy { from, to, len } if n > 0 => {
            let from = pos(from);
            let block = input[from..(from + len).min(n)].to_vec();
            let to = pos(to);
            input.splice(to..to, block);
        }
        _ => {}
    }
}

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name).map_or(default, |v| {
        v.parse()
            .unwrap_or_else(|_| panic!("{name}={v}: not a number"))
    })
}

/// Runs `name`'s target on `cases` mutated seeds (or `ATMO_FUZZ_CASES`);
/// panics with the shrunk failure.
fn fuzz(name: &str, cases: u32) {
    let (_, target) = atmo_fuzz::TARGETS
        .into_iter()
        .find(|(n, _)| *n == name)
        .unwrap();
    let seeds: Vec<Vec<u8>> = atmo_fuzz::corpus_files(&[atmo_fuzz::corpus_dir(name)])
        .iter()
        .map(|f| std::fs::read(f).unwrap())
        .collect();
    assert!(!seeds.is_empty(), "{name}: no seeds");
    let config = Config {
        cases: env_or("ATMO_FUZZ_CASES", cases),
        failure_persistence: None,
        ..Config::default()
    };
    let mut seed = [0u8; 32];
    seed[..8].copy_from_slice(&env_or::<u64>("ATMO_FUZZ_SEED", 0).to_le_bytes());
    let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &seed);
    let mut runner = TestRunner::new_with_rng(config, rng);
    let input = |(seed, mutations): &(usize, Vec<Mutation>)| {
        let mut bytes = seeds[*seed].clone();
        for m in mutations {
            apply(&mut bytes, m);
        }
        bytes
    };
    let strategy = (0..seeds.len(), prop::collection::vec(mutation(), 1..=8));
    let result = runner.run(&strategy, |case| {
        target(&input(&case));
        Ok(())
    });
    if let Err(TestError::Fail(reason, case)) = result {
        let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz-failures");
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join(format!("{name}.bin"));
        std::fs::write(&file, input(&case)).unwrap();
        panic!(
            "{name}: {reason}\nseed {} with {:?}\ninput written to {} \
             (replay: cd fuzz && cargo run --bin {name} -- FILE)",
            case.0,
            case.1,
            file.display()
        );
    } else if let Err(e) = result {
        panic!("{name}: {e}");
    }
}

#[test]
fn recording_csv_survives_mutated_seeds() {
    fuzz("recording_csv", 20_000);
}

#[test]
fn config_toml_survives_mutated_seeds() {
    fuzz("config_toml", 20_000);
}

#[test]
fn cdr_decode_survives_mutated_seeds() {
    fuzz("cdr_decode", 50_000);
}

#[test]
fn mcap_read_survives_mutated_seeds() {
    fuzz("mcap_read", 3000);
}

#[test]
fn mcap_recover_survives_mutated_seeds() {
    fuzz("mcap_recover", 2000);
}

/// The mutations do what they say (a mutation that silently did nothing
/// would make the cases above weaker than they look).
#[test]
fn the_mutations_change_the_input() {
    let seed = b"t,vx\n0.0,1.0\n".to_vec();
    let cases = [
        Mutation::FlipBit { at: 0, bit: 0 },
        Mutation::SetByte { at: 1, value: b'x' },
        Mutation::SetInt {
            at: 3,
            value: 9,
            width: 8,
        },
        Mutation::Delete { at: 5, len: 3 },
        Mutation::Insert {
            at: 100,
            bytes: vec![0],
        },
        Mutation::Token { at: 9, token: 0 },
        Mutation::Copy {
            from: 0,
            to: 4,
            len: 5,
        },
    ];
    for m in cases {
        let mut input = seed.clone();
        apply(&mut input, &m);
        assert_ne!(input, seed, "{m:?}");
    }
    let mut input = seed.clone();
    apply(&mut input, &Mutation::Token { at: 9, token: 0 });
    assert_eq!(input, b"t,vx\n0.0,nan1.0\n");
}
