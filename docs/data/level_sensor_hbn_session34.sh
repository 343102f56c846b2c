#!/bin/bash
# hbn's default with the HBN sensor [x_{k-1}, y_{k-1}, x_k] and with a sensor GP on [x_{k-1}, x_k]
# (HBN_SENSOR_LEVEL=1), on the judged grid's protocol (three 1000-sample training logs with one
# input, a test log with another), one JSON line per model: test nRMSE, 2-sigma coverage and
# mean NEES of the default mode, and the chosen candidate's held-out nRMSE and NLPD.
# Needs the hbn binary of the branch wip/level-sensor (session 34), where the switch exists:
#   git worktree add /tmp/wt wip/level-sensor && (cd /tmp/wt && cargo build --release -p hbn-cli)
#   HBN_LEVEL_BIN=/tmp/wt/target/release/hbn docs/data/level_sensor_hbn_session34.sh SYSTEMS GAINS SEEDS OUT.jsonl
#   python3 docs/data/level_sensor_hbn_summary_session34.py OUT.jsonl [MORE.jsonl]
H=${HBN_LEVEL_BIN:?set HBN_LEVEL_BIN to the wip/level-sensor build of hbn}
out=$4
for sys in ${1//,/ }; do for g in ${2//,/ }; do for S in ${3//,/ }; do
  d=$(mktemp -d)
  for k in 1 2 3; do $H -q simulate --system $sys --steps 1000 --input-seed $S --seed $((10*S+k)) --noise-gain $g --out $d/tr$k.mcap >/dev/null; done
  $H -q simulate --system $sys --steps 1000 --input-seed $((S+1)) --seed $((10*S+11)) --noise-gain $g --out $d/te.mcap >/dev/null
  for lv in 0 1; do
    HBN_SENSOR_LEVEL=$lv $H -q train --log $d/tr1.mcap --log $d/tr2.mcap --log $d/tr3.mcap --seed $S --out $d/m$lv.hbn >/dev/null 2>&1
    r=$(HBN_SENSOR_LEVEL=$lv $H eval --model $d/m$lv.hbn --log $d/te.mcap --json 2>/dev/null | python3 -c "
import json,sys; d=json.load(sys.stdin); m=json.load(open('$d/m$lv.hbn'))
mode=m['model']['tuning']['default_mode'].replace('-','_')
c=[x for x in m['model']['summary']['validation']['candidates'] if x['chosen']][0]['scored'][1]
print(json.dumps({'mode':mode,'nrmse':d['nrmse'][mode], 'cov2':d['calibration'][mode]['coverage_2sigma'], 'nees':d['calibration'][mode]['mean_nees'], 'ho_nrmse':c['nrmse'], 'ho_nlpd':c['calibration']['nlpd']}))" 2>&1)
    echo "{\"system\":\"$sys\",\"gain\":$g,\"seed\":$S,\"level\":$lv,\"r\":$r}" >> $out
  done
  rm -rf $d
done; done; done
