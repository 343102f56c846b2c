#!/bin/bash
# hbn's default (sensor inputs `thesis,state`: a sensor of the state only tried on held-out
# data) against the default without that candidate (`--sensor-inputs thesis`), in the same
# run, on the judged grid's protocol (three 1000-sample training logs with one input, a test
# log with another). One JSON line per model: test nRMSE, 2-sigma coverage and mean NEES of the
# default mode, the chosen candidate and the training's wall seconds.
#   docs/data/sensor_inputs_session35.sh SYSTEMS GAINS SEEDS OUT.jsonl
#   python3 docs/data/sensor_inputs_summary_session35.py OUT.jsonl [MORE.jsonl]
# VARIANTS="default" trains the default only (session 36: its state candidate changed, the
# thesis-only variant did not).
H=${HBN_BIN:-target/release/hbn}
VARIANTS=${VARIANTS:-default thesis}
out=$4
for sys in ${1//,/ }; do for g in ${2//,/ }; do for S in ${3//,/ }; do
  d=$(mktemp -d)
  for k in 1 2 3; do $H -q simulate --system $sys --steps 1000 --input-seed $S --seed $((10*S+k)) --noise-gain $g --out $d/tr$k.mcap >/dev/null; done
  $H -q simulate --system $sys --steps 1000 --input-seed $((S+1)) --seed $((10*S+11)) --noise-gain $g --out $d/te.mcap >/dev/null
  for variant in $VARIANTS; do
    flag=""; [ $variant = thesis ] && flag="--sensor-inputs thesis"
    t0=$(date +%s.%N)
    $H -q train --log $d/tr1.mcap --log $d/tr2.mcap --log $d/tr3.mcap --seed $S $flag --out $d/m.hbn >/dev/null 2>&1
    t1=$(date +%s.%N)
    r=$($H eval --model $d/m.hbn --log $d/te.mcap --json 2>/dev/null | python3 -c "
import json,sys; d=json.load(sys.stdin); m=json.load(open('$d/m.hbn'))
mode=m['model']['tuning']['default_mode'].replace('-','_')
c=[x for x in m['model']['summary']['validation']['candidates'] if x['chosen']][0]
p=m['model']['params']
print(json.dumps({'mode':mode,'nrmse':d['nrmse'][mode],'cov2':d['calibration'][mode]['coverage_2sigma'],'nees':d['calibration'][mode]['mean_nees'],'sensor':p.get('sensor_inputs','thesis'),'inducing':p.get('n_inducing'),'lags':p.get('lags',[]),'ho_nrmse':c['scored'][1]['nrmse']}))" 2>&1)
    echo "{\"system\":\"$sys\",\"gain\":$g,\"seed\":$S,\"variant\":\"$variant\",\"seconds\":$(python3 -c "print(round($t1-$t0,2))"),\"r\":$r}" >> $out
  done
  rm -rf $d
done; done; done
