#!/usr/bin/env bash
# Coverage-guided fuzzing of the input parsers (fuzz/) with cargo afl
# (AFL++ built from the sources the `afl` crate ships, by cargo-afl).
#
#   scripts/fuzz.sh [TARGET...]     every target (fuzz/src/lib.rs) if none named
#
# FUZZ_SECONDS (default 20) bounds each target's run (afl-fuzz -V); FUZZ_EXECS
# also stops a target after about that many executions (afl-fuzz -E). Each run
# starts from the committed seeds in fuzz/corpus/<target>/ (the mcap targets
# share fuzz/corpus/mcap/); a seed that crashes fails the target at once.
# Installs cargo-afl under $target/fuzz/cargo-afl and AFL++ under
# $target/fuzz/xdg (cached: a second run builds nothing). Prints per target the
# executions, rate, paths and crashes, then `N passed, M failed`; exits
# non-zero on any crash or hang (a hang: one input over FUZZ_HANG_MS, default
# 10000 ms). Findings stay in $target/fuzz/out/<target>/default/{crashes,hangs}.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
target=${CARGO_TARGET_DIR:-target}
case $target in /*) ;; *) target=$root/$target ;; esac
fuzz_dir=$target/fuzz
seconds=${FUZZ_SECONDS:-20}
execs=${FUZZ_EXECS:-}
hang_ms=${FUZZ_HANG_MS:-10000}
all_targets=(recording_csv config_toml cdr_decode mcap_read mcap_recover)
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=("${all_targets[@]}")

export PATH=$fuzz_dir/cargo-afl/bin:$PATH
# cargo-afl keeps AFL++ and its runtime under $XDG_DATA_HOME/afl.rs.
export XDG_DATA_HOME=$fuzz_dir/xdg
export CARGO_TARGET_DIR=$fuzz_dir/build
mkdir -p "$XDG_DATA_HOME" "$fuzz_dir/tmp"

if ! cargo afl --version >/dev/null 2>&1; then
    echo "fuzz: installing cargo-afl 0.18 from crates.io into $fuzz_dir/cargo-afl"
    cargo install cargo-afl --version '^0.18' --locked --root "$fuzz_dir/cargo-afl"
fi
if ! compgen -G "$XDG_DATA_HOME/afl.rs/*/*/afl/bin/afl-fuzz" >/dev/null; then
    echo "fuzz: building AFL++ and its runtime (cargo afl config --build)"
    cargo afl config --build --force
fi

echo "fuzz: building the targets (cargo afl build --release --features afl)"
# An explicit --target keeps the instrumentation off build scripts and proc
# macros; the wrapper keeps it to the crates that read the fuzzed bytes.
host=$(rustc -vV | sed -n 's/^host: //p')
(cd fuzz && RUSTC_WRAPPER=$root/fuzz/rustc-wrapper.sh \
    cargo afl build --release --features afl --bins --target "$host")
bin_dir=$CARGO_TARGET_DIR/$host/release

# A shared machine and CI: no core binding, no CPU governor or core-dump
# checks, no screen UI; the targets' scratch files under target/.
export AFL_NO_AFFINITY=1 AFL_SKIP_CPUFREQ=1 AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1
export AFL_NO_UI=1 AFL_QUIET=1 TMPDIR=$fuzz_dir/tmp

corpus_of() {
    case $1 in
        mcap_*) echo "$root/fuzz/corpus/mcap" ;;
        *) echo "$root/fuzz/corpus/$1" ;;
    esac
}

stat_of() { sed -n "s/^$1 *: *//p" "$2" | head -n1; }

passed=0
failed=0
for t in "${targets[@]}"; do
    out=$fuzz_dir/out/$t
    rm -rf "$out"
    mkdir -p "$out"
    args=(-i "$(corpus_of "$t")" -o "$out" -V "$seconds" -t "$hang_ms")
    [ -z "$execs" ] || args+=(-E "$execs")
    start=$(date +%s)
    rc=0
    cargo afl fuzz "${args[@]}" "$bin_dir/$t" >"$out/afl.log" 2>&1 || rc=$?
    elapsed=$(($(date +%s) - start))
    stats=$out/default/fuzzer_stats
    if [ ! -f "$stats" ]; then
        echo "FAIL $t: afl-fuzz exited $rc without stats (a seed crashed or AFL++ could not start):"
        tail -n 25 "$out/afl.log"
        failed=$((failed + 1))
        continue
    fi
    crashes=$(find "$out/default/crashes" -type f -name 'id:*' | wc -l)
    hangs=$(find "$out/default/hangs" -type f -name 'id:*' | wc -l)
    line="$t: $(stat_of execs_done "$stats") execs in ${elapsed} s ($(stat_of execs_per_sec "$stats") execs/s at the end), $(stat_of corpus_count "$stats") paths, $crashes crashes, $hangs hangs"
    if [ "$rc" -ne 0 ] || [ "$crashes" -gt 0 ] || [ "$hangs" -gt 0 ]; then
        echo "FAIL $line (afl-fuzz exit $rc; inputs in $out/default/{crashes,hangs})"
        failed=$((failed + 1))
    else
        echo "ok   $line"
        passed=$((passed + 1))
    fi
done

echo "fuzz: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
