#!/usr/bin/env bash
# RUSTC_WRAPPER of the fuzz build (scripts/fuzz.sh). `cargo afl build` puts
# the AFL++ coverage instrumentation, opt-level 3 and one codegen unit on every
# crate; built that way the ~300 crates under the targets (rustdds, iceoryx2,
# Clarabel, plotters, tokio...) take about an hour on two cores. Only the
# crates that read the fuzzed bytes keep it: ours, the MCAP, TOML and CDR
# readers and what they decode with. The rest is built plainly at opt-level 1
# (generic code the parsers use, serde's or nalgebra's, is instrumented where
# our crates instantiate it). Set FUZZ_INSTRUMENT_ALL=1 to instrument all.
rustc=$1
shift
name=
prev=
for arg in "$@"; do
    [ "$prev" = --crate-name ] && name=$arg
    prev=$arg
done
case ${FUZZ_INSTRUMENT_ALL:-}:$name in
    1:* | *:atmo_* | *:mcap | *:binrw | *:crc32fast | *:lz4 | *:lz4_flex | *:zstd | *:zstd_safe \
        | *:toml | *:toml_edit | *:toml_parser | *:toml_datetime | *:serde_spanned | *:winnow \
        | *:cdr_encoding | *:serde_path_to_error | *:byteorder)
        exec "$rustc" "$@"
        ;;
esac
args=()
drop_next=
for arg in "$@"; do
    if [ "$arg" = -C ]; then
        drop_next=pending
        continue
    fi
    if [ "$drop_next" = pending ]; then
        drop_next=
        case $arg in
            passes=sancov* | llvm-args=-sanitizer-coverage* | codegen-units=1) continue ;;
            opt-level=*) arg=opt-level=1 ;;
        esac
        args+=(-C "$arg")
        continue
    fi
    args+=("$arg")
done
exec "$rustc" "${args[@]}"
