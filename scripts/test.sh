#!/usr/bin/env bash
# Runs every test of hbn: Rust (unit, end-to-end, CLI) and Python (the wheel), on a fresh
# machine with only Rust, Python 3 and pip. Usage: ./scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

echo "== hbn-core builds without std and without alloc"
cargo build -p hbn-core --no-default-features

echo "== hbn-ffi (with hbn-core) builds for a Cortex-M4F (thumbv7em-none-eabihf; optional: needs rustup)"
# The firmware target of docs/firmware.md. A dependency that builds only on the host (one did:
# cpufeatures, before it was made x86-64-only) breaks firmware builds and no host test sees it.
if rustup target list --installed 2>/dev/null | grep -qx thumbv7em-none-eabihf \
  || timeout 300 rustup target add thumbv7em-none-eabihf >/dev/null 2>&1; then
  # docs/firmware.md's command, which builds hbn-core with it.
  cargo build --release -p hbn-ffi --no-default-features --target thumbv7em-none-eabihf \
    --config 'profile.release.panic="abort"'
else
  echo "   skipped: the thumbv7em-none-eabihf target is not installed and rustup could not add it"
fi

echo "== hbn-core: the estimator step links with no panic path (no-panic, fat LTO)"
cargo test --release --manifest-path crates/hbn-core/nopanic/Cargo.toml

echo "== Rust tests (release: the end-to-end tests train GPs; also builds target/release/hbn;"
echo "   tests/firmware.rs builds the C and no_std Rust firmware examples: needs make and cc)"
cargo test --release --workspace --exclude hbn-py

echo "== The Rust user example: MCAP logs -> model -> streaming filter (examples/train_and_stream.rs)"
cargo run --release --quiet --example train_and_stream

echo "== The AVX2 code of target/release/hbn holds no legacy-SSE instruction (objdump; optional)"
python3 scripts/check_avx2_encoding.py target/release/hbn

echo "== Fuzz smoke: each cargo-fuzz target, a fixed seed and run count (needs nightly and cargo-fuzz; optional)"
# The corpora also replay on stable in tests/fuzz_replay.rs (above). The smoke is
# deterministic: a fresh scratch corpus, -seed=1 and a fixed number of executions, so CI
# runs exactly what passed here; exploration is the campaign's job (scripts/fuzz_campaign.sh,
# docs/reliability.md), and every crash it finds becomes a committed regression input. The
# memory limits are the campaign's (the mcap crate reserves a string's claimed length before
# reading it, an out-of-memory only under libFuzzer's default 2 GiB limit).
if cargo +nightly --version >/dev/null 2>&1 && cargo +nightly fuzz --version >/dev/null 2>&1; then
  SMOKE="$ROOT/target/fuzz-smoke"
  for t in $(cargo +nightly fuzz list); do
    case "$t" in
      mcap_ingest) runs=2000 ;;
      model_load) runs=10000 ;;
      *) runs=20000 ;;
    esac
    rm -rf "$SMOKE/corpus/$t" "$SMOKE/artifacts/$t"
    mkdir -p "$SMOKE/corpus/$t" "$SMOKE/artifacts/$t"
    log="$SMOKE/$t.log"
    # Exits non-zero on a crash (the input is saved under $SMOKE/artifacts/$t/).
    if ! cargo +nightly fuzz run "$t" "$SMOKE/corpus/$t" "fuzz/corpus/$t" -- \
      -seed=1 -runs="$runs" -print_final_stats=1 -rss_limit_mb=8192 -malloc_limit_mb=8192 \
      -artifact_prefix="$SMOKE/artifacts/$t/" \
      >"$log" 2>&1; then
      tail -n 40 "$log" >&2
      echo "fuzz target $t failed (log: $log)" >&2
      exit 1
    fi
    echo "$t: $(grep -E '^stat::number_of_executed_units' "$log" || echo 'no stats')"
  done
else
  echo "notice: cargo +nightly or cargo-fuzz is not installed: fuzz smoke skipped"
fi

echo "== Python: a private virtual environment with numpy, scikit-learn, matplotlib and pytest"
VENV="$ROOT/target/py-test-venv"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install numpy scikit-learn matplotlib pytest "dask[distributed]"

echo "== Python: build the wheel (cargo compiles the engine in release mode: a few minutes the"
echo "   first time; pip -v shows cargo's progress) and install it"
"$VENV/bin/python" -m pip install -v --force-reinstall --no-deps ./hbn-py

echo "== Python tests (the wheel, then the baselines of benches/baselines; the LSTM skips without torch)"
HBN_BIN="$ROOT/target/release/hbn" "$VENV/bin/python" -m pytest -q hbn-py/tests
HBN_BIN="$ROOT/target/release/hbn" "$VENV/bin/python" -m pytest -q benches/baselines benches/test_slow_camera_bench.py benches/test_unmeasured_logs.py benches/test_more_data.py

echo "== Every code block of the READMEs, ARCHITECTURE.md, CONTRIBUTING.md and docs/ (shell with target/release/hbn on"
echo "   PATH, Python with the wheel; Rust blocks ran above as doctests)"
"$VENV/bin/python" scripts/check_docs.py --self-test
"$VENV/bin/python" scripts/check_docs.py --python "$VENV/bin/python" --hbn "$ROOT/target/release/hbn"
