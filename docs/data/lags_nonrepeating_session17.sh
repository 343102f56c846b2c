#!/bin/bash
# Lags on non-repeating logs (docs/memory.md). usage: HBN_BIN=target/release/hbn OUT=DIR
# docs/data/lags_nonrepeating_session17.sh SYSTEM  -> one line per (gain, seed, variant)
H=$(realpath ${HBN_BIN:-target/release/hbn})
OUT=${OUT:-/tmp/nr}
sys=$1
for gain in 1 10; do for seed in 1 2; do
  d=$OUT/$sys-$gain-$seed; mkdir -p $d; cd $d
  $H -q simulate --system $sys --steps 5000 --input-seed $seed --seed $((10*seed+1)) --noise-gain $gain --out train.mcap
  $H -q simulate --system $sys --steps 1000 --input-seed $((seed+100)) --seed $((10*seed+2)) --noise-gain $gain --out test.mcap
  for v in none 1; do
    $H -q train --log train.mcap --out m_$v.hbn --lags $v > /dev/null 2>&1
    mode=$($H inspect m_$v.hbn --json | python3 -c "import sys,json; d=json.load(sys.stdin); print(d['filter']['tuning']['default_mode'])" 2>/dev/null)
    n=$($H eval --model m_$v.hbn --log test.mcap --json | python3 -c "import sys,json; d=json.load(sys.stdin); print(json.dumps(d['nrmse']))")
    echo "$sys $gain $seed lags=$v mode=$mode $n"
  done
done; done
