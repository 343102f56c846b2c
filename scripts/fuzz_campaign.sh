#!/usr/bin/env bash
# The fuzz campaign of docs/reliability.md: runs each cargo-fuzz target (nightly) for RUNS
# executions (default 10^6) or at most MAX_S seconds (default 1200), one process each,
# starting from the committed corpus fuzz/corpus/<target>. New inputs go to a scratch corpus
# under target/fuzz-campaign/ (not into the committed one); crashes to
# target/fuzz-campaign/artifacts/<target>/. Prints, per target, the final status line (cov:,
# ft:, corp:, exec/s) and the number of executions. Afterwards, to keep only the new inputs
# that add coverage in the committed corpus:
#   cargo +nightly fuzz run <target> fuzz/corpus/<target> target/fuzz-campaign/corpus/<target> -- -merge=1
# Usage: ./scripts/fuzz_campaign.sh [target...]   (RUNS=... MAX_S=... to change the budget;
# SANITIZER=none builds without AddressSanitizer, several times faster for the slow
# mcap_ingest target; safe Rust gains little from ASan, and the RSS limit still applies)
# The malloc limit is 8 GiB, not libFuzzer's 2 GiB: the mcap crate reserves a string's claimed
# length (up to 4 GiB) before reading it, which only reserves address space in a normal build
# (the read then fails with an error), but counts as an out-of-memory crash under libFuzzer.
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-1000000}
MAX_S=${MAX_S:-1200}
SANITIZER=${SANITIZER:-address}
# Builds of another sanitizer get their own target directory, so that two campaigns can run at
# once without rebuilding each other's targets.
# FUZZ_FLAGS: more `cargo fuzz run` flags, e.g. FUZZ_FLAGS=-O (no debug assertions and no
# overflow checks: how hbn ships). Such builds also get their own target directory.
read -r -a EXTRA <<<"${FUZZ_FLAGS:-}"
TARGET_DIR=()
if [ "$SANITIZER" != address ] || [ ${#EXTRA[@]} -gt 0 ]; then
  TARGET_DIR=(--target-dir "fuzz/target-$SANITIZER${FUZZ_FLAGS:+-opt}")
fi
OUT=target/fuzz-campaign
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  mapfile -t targets < <(cargo +nightly fuzz list)
fi
for t in "${targets[@]}"; do
  mkdir -p "$OUT/corpus/$t" "$OUT/artifacts/$t"
  log="$OUT/$t.log"
  status=0
  cargo +nightly fuzz run -s "$SANITIZER" "${TARGET_DIR[@]}" ${EXTRA[@]+"${EXTRA[@]}"} "$t" "$OUT/corpus/$t" "fuzz/corpus/$t" -- \
    -runs="$RUNS" -max_total_time="$MAX_S" -print_final_stats=1 \
    -rss_limit_mb=8192 -malloc_limit_mb=8192 \
    -artifact_prefix="$OUT/artifacts/$t/" >"$log" 2>&1 || status=$?
  last=$(grep -E '^#[0-9]+' "$log" | tail -n 1 || true)
  execs=$(grep -E '^stat::number_of_executed_units' "$log" | awk '{print $2}' || true)
  echo "$t: exit $status, executions ${execs:-?}; $last"
  if [ "$status" -ne 0 ]; then
    echo "  crash inputs: $(ls "$OUT/artifacts/$t")"
  fi
done
