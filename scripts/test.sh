#!/usr/bin/env bash
# Runs every test of hbn: Rust (unit, end-to-end, CLI) and Python (the wheel), on a fresh
# machine with only Rust, Python 3 and pip. Usage: ./scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

echo "== hbn-core builds without std and without alloc"
cargo build -p hbn-core --no-default-features

echo "== hbn-core: the estimator step links with no panic path (no-panic, fat LTO)"
cargo test --release --manifest-path crates/hbn-core/nopanic/Cargo.toml

echo "== Rust tests (release: the end-to-end tests train GPs; also builds target/release/hbn)"
cargo test --release --workspace --exclude hbn-py

echo "== Fuzz targets: a short smoke run each when nightly and cargo-fuzz are present"
# The committed corpora already replay on stable above (tests/fuzz_replay.rs); this adds a few
# seconds of coverage-guided mutation per target. docs/reliability.md has the long campaign.
if cargo +nightly --version >/dev/null 2>&1 && cargo +nightly fuzz --version >/dev/null 2>&1; then
  for target in cdr ros2msg signal_path model_load mcap_ingest step; do
    (cd fuzz && cargo +nightly fuzz run -O "$target" -- -max_total_time=5 -print_final_stats=1 \
      2>&1 | grep -E "^stat::number_of_executed_units|ERROR|panicked" || true)
    # A crash makes cargo fuzz exit non-zero and leaves an artifact: fail the run on it.
    if ls fuzz/artifacts/"$target"/crash-* >/dev/null 2>&1; then
      echo "fuzz target $target found a crash: see fuzz/artifacts/$target"; exit 1
    fi
  done
else
  echo "(skipped: needs the nightly toolchain and cargo-fuzz: cargo install cargo-fuzz)"
fi

echo "== Python: build and install the wheel into a private virtual environment"
VENV="$ROOT/target/py-test-venv"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install --quiet numpy scikit-learn matplotlib pytest
"$VENV/bin/python" -m pip install --quiet --force-reinstall --no-deps ./hbn-py

echo "== Python tests (the wheel, then the baselines of benches/baselines; the LSTM skips without torch)"
HBN_BIN="$ROOT/target/release/hbn" "$VENV/bin/python" -m pytest -q hbn-py/tests
HBN_BIN="$ROOT/target/release/hbn" "$VENV/bin/python" -m pytest -q benches/baselines

echo "== The README's Python snippets run as written"
"$VENV/bin/python" scripts/check_docs.py
