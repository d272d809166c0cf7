#!/usr/bin/env bash
# Fuzzes every input parser for a bounded time: `make fuzz`, or `scripts/fuzz.sh [TARGET...]`
# (targets: exr hdr png jpeg ktx2 zstd dds ktx1 pipeline ownership budget; default all).
#
#   FUZZ_SECONDS=60     time per target
#   FUZZ_ENGINE=auto    auto: cargo-fuzz (libFuzzer, coverage-guided) when it builds, else the
#                       built-in mutation fuzzer; `cargo-fuzz` or `builtin` to force one
#   FUZZ_RSS_MB=4096    libFuzzer's memory limit (the readers accept images up to 2^28 texels)
#   IBL_FUZZ_STRICT=1   also stop at panics the readers catch inside third-party decoders
#
# cargo-fuzz needs nightly flags; on a stable toolchain RUSTC_BOOTSTRAP=1 lets them through.
# Crash inputs are copied into fuzz/regressions/<target>/ (replayed by `cargo test -p ibl-core`
# and `cargo test --manifest-path fuzz/Cargo.toml`); the script exits non-zero if any was found.
set -uo pipefail
cd "$(dirname "$0")/.."

SECS=${FUZZ_SECONDS:-60}
ENGINE=${FUZZ_ENGINE:-auto}
RSS=${FUZZ_RSS_MB:-4096}
ALL=(exr hdr png jpeg ktx2 zstd dds ktx1 pipeline ownership budget)
if [ $# -gt 0 ]; then TARGETS=("$@"); else TARGETS=("${ALL[@]}"); fi
for t in "${TARGETS[@]}"; do
    case " ${ALL[*]} " in *" $t "*) ;; *) echo "fuzz: unknown target '$t' (${ALL[*]})" >&2; exit 2 ;; esac
done
export RUSTC_BOOTSTRAP=1
mkdir -p fuzz/work

if [ "$ENGINE" != builtin ] && ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz: installing cargo-fuzz (a few minutes, once)"
    cargo install cargo-fuzz --locked >fuzz/work/install.log 2>&1 \
        || echo "fuzz: cannot install cargo-fuzz (see fuzz/work/install.log)"
fi
if [ "$ENGINE" = auto ]; then
    if cargo fuzz --version >/dev/null 2>&1; then ENGINE=cargo-fuzz; else ENGINE=builtin; fi
fi

features() { if [ "$1" = pipeline ]; then echo ""; else echo "--no-default-features"; fi; }

crashes=0
summary=()

# The built-in fuzzer: no coverage feedback, but no nightly features either.
builtin() {
    local t=$1 log=fuzz/work/$1.builtin.log
    echo "fuzz $t: built-in mutation fuzzer, ${SECS} s"
    local before after
    before=$(ls fuzz/regressions/"$t" 2>/dev/null | wc -l)
    if [ "$t" = pipeline ]; then
        FUZZ_SECONDS=$SECS FUZZ_TARGETS=$t cargo test --release --manifest-path fuzz/Cargo.toml \
            --test mutation -- --ignored mutation_fuzz_long --nocapture >"$log" 2>&1
    elif [ "$t" = ownership ] || [ "$t" = budget ]; then
        FUZZ_SECONDS=$SECS FUZZ_TARGETS=$t cargo test -p ibl-core --test fuzz_owned \
            -- --ignored mutation_fuzz_long --nocapture >"$log" 2>&1
    else
        FUZZ_SECONDS=$SECS FUZZ_TARGETS=$t cargo test -p ibl-core --test fuzz_regressions \
            -- --ignored mutation_fuzz_long --nocapture >"$log" 2>&1
    fi
    local rc=$?
    after=$(ls fuzz/regressions/"$t" 2>/dev/null | wc -l)
    local line
    line=$(grep -E "^fuzz $t:" "$log" | tail -1)
    if [ $rc -ne 0 ] || [ "$after" -gt "$before" ]; then
        crashes=$((crashes + 1))
        summary+=("$t: FAILED (built-in; exit $rc; $((after - before)) new files in fuzz/regressions/$t; log $log) ${line#fuzz $t: }")
    else
        summary+=("$t: ok (built-in) ${line#fuzz $t: }")
    fi
}

libfuzzer() {
    local t=$1 log=fuzz/work/$1.log
    # shellcheck disable=SC2046
    if ! cargo fuzz build $(features "$t") "$t" >fuzz/work/"$t".build.log 2>&1; then
        echo "fuzz $t: cargo fuzz build failed (fuzz/work/$t.build.log); built-in fuzzer instead"
        builtin "$t"
        return
    fi
    echo "fuzz $t: cargo-fuzz, ${SECS} s"
    rm -rf fuzz/artifacts/"$t"
    mkdir -p fuzz/work/corpus/"$t" fuzz/regressions/"$t"
    local dict=()
    [ -f fuzz/dicts/"$t".dict ] && dict=(-dict="$PWD/fuzz/dicts/$t.dict")
    # The first corpus folder receives what libFuzzer finds; the seeds stay read-only.
    # shellcheck disable=SC2046
    cargo fuzz run $(features "$t") "$t" "$PWD"/fuzz/{work/corpus,corpus,regressions}/"$t" -- \
        -max_total_time="$SECS" -rss_limit_mb="$RSS" -malloc_limit_mb="$RSS" -timeout=60 \
        -print_final_stats=1 "${dict[@]}" >"$log" 2>&1
    local rc=$?
    local runs found=0
    runs=$(grep -oE "^Done [0-9]+ runs in [0-9]+ second" "$log" | tail -1)
    runs=${runs#Done }
    for a in fuzz/artifacts/"$t"/*; do
        [ -f "$a" ] || continue
        found=$((found + 1))
        mkdir -p fuzz/regressions/"$t"
        cp "$a" fuzz/regressions/"$t"/
        echo "fuzz $t: kept $(basename "$a") in fuzz/regressions/$t/"
    done
    if [ $rc -ne 0 ] || [ $found -gt 0 ]; then
        crashes=$((crashes + 1))
        summary+=("$t: FAILED (exit $rc, $found artefacts kept in fuzz/regressions/$t; log $log) ${runs:-}")
        grep -m3 -E "panicked at|ERROR: libFuzzer|SUMMARY" "$log" | sed 's/^/    /'
    else
        summary+=("$t: ok, ${runs:-? runs}s")
    fi
}

for t in "${TARGETS[@]}"; do
    if [ "$ENGINE" = cargo-fuzz ]; then libfuzzer "$t"; else builtin "$t"; fi
done

echo
echo "fuzz summary (${SECS} s per target):"
for s in "${summary[@]}"; do echo "  $s"; done
if [ $crashes -gt 0 ]; then
    echo "fuzz: $crashes target(s) crashed; reproduce with cargo fuzz run TARGET fuzz/regressions/TARGET/FILE"
    exit 1
fi
