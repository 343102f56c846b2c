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
