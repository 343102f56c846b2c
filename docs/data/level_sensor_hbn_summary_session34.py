"""Summary of docs/data/level_sensor_hbn_session34.sh's lines: per run, the test nRMSE with the
HBN sensor and with the level sensor, their held-out scores, and which the default's rule would
choose between the two (the lower held-out NLPD among those no less accurate held out than the
HBN-sensor model); per noise gain, geometric means of the ratios to the HBN sensor.

usage: python3 docs/data/level_sensor_hbn_summary_session34.py RUNS.jsonl [MORE.jsonl ...]"""
import sys, json, collections, math
d = collections.defaultdict(dict)
for p in sys.argv[1:]:
    for l in open(p):
        r = json.loads(l)
        d[(r["system"], r["gain"], r["seed"])][r["level"]] = r["r"]
by_gain = collections.defaultdict(lambda: {"level": [], "choice": [], "best": []})
for k, v in sorted(d.items(), key=lambda kv: (kv[0][1], kv[0][0], kv[0][2])):
    if 0 not in v or 1 not in v:
        continue
    a, b = v[0], v[1]
    # the default's rule between the two chosen models: the lower held-out NLPD among those
    # no less accurate held out than the HBN-sensor model
    pick = b if (b["ho_nrmse"] <= a["ho_nrmse"] and b["ho_nlpd"] < a["ho_nlpd"]) else a
    g = by_gain[k[1]]
    g["level"].append(math.log(b["nrmse"] / a["nrmse"]))
    g["choice"].append(math.log(pick["nrmse"] / a["nrmse"]))
    g["best"].append(math.log(min(a["nrmse"], b["nrmse"]) / a["nrmse"]))
    print(f"{k[0]:14s} g{k[1]} s{k[2]}  test {a['nrmse']:.4f} -> {b['nrmse']:.4f}   held out nRMSE {a['ho_nrmse']:.4f} / {b['ho_nrmse']:.4f} NLPD {a['ho_nlpd']:.3f} / {b['ho_nlpd']:.3f}   chosen: {'level' if pick is b else 'hbn'} -> {pick['nrmse']:.4f}  cov2 {pick['cov2']}")
gm = lambda v: math.exp(sum(v) / len(v))
for g, v in sorted(by_gain.items()):
    worse = sum(x > 1e-12 for x in v["choice"]); better = sum(x < -1e-12 for x in v["choice"])
    print(f"gain {g}: {len(v['level'])} runs; level sensor alone {gm(v['level']):.3f}x, held-out choice {gm(v['choice']):.3f}x (better in {better}, worse in {worse}), best of both {gm(v['best']):.3f}x")
