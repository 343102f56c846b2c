"""Training time with and without validation, one process at a time, on demo-style logs
(three 1000-sample runs of one input, independent noise) for several systems and gains. With
--thesis (session 35) also the default without its state-only sensor candidate
(`--sensor-inputs thesis`, the default before session 35), in the same run.
usage: training_time_session25.py [--thesis] HBN_BIN OUT.json [LOG_DIR]

The logs are simulated into LOG_DIR (default ./training-time-logs) on first use and kept,
so two binaries are timed on the same files. Each training runs once, one process at a
time; run it on an idle machine (single runs vary by about 10%)."""
import json, subprocess, sys, time, os, statistics
args = [a for a in sys.argv[1:] if a != "--thesis"]
thesis = "--thesis" in sys.argv[1:]
hbn, out = args[0], args[1]
reps = 1
d = args[2] if len(args) > 2 else "training-time-logs"
os.makedirs(d, exist_ok=True)
systems = ["bouc-wen", "duhem", "preisach", "soft-actuator", "maxwell-slip", "generalized-pi"]
gains = [0, 1, 3, 10]
rows = []
for s in systems:
    for g in gains:
        logs = []
        for r in (1, 2, 3):
            p = f"{d}/{s}_{g}_{r}.mcap"
            if not os.path.exists(p):
                subprocess.run([hbn, "simulate", "--system", s, "--steps", "1000", "--input-seed", "1",
                                "--seed", str(10 + r), "--noise-gain", str(g), "--out", p, "-q"], check=True,
                               stdout=subprocess.DEVNULL)
            logs += ["--log", p]
        t = {}
        variants = [("v0", ["--validation", "0"]), ("default", [])]
        if thesis:
            variants.append(("thesis", ["--sensor-inputs", "thesis"]))
        for name, extra in variants:
            ts = []
            for _ in range(reps):
                t0 = time.perf_counter()
                subprocess.run([hbn, "train", *logs, "--out", f"{d}/m.hbn", "-q", *extra], check=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                ts.append(time.perf_counter() - t0)
            t[name] = min(ts)
        row = {"system": s, "gain": g, **t, "ratio": t["default"] / t["v0"]}
        if thesis:
            row["ratio_thesis"] = t["thesis"] / t["v0"]
        rows.append(row)
        note = f" thesis {t['thesis']:.2f} s ({row['ratio_thesis']:.2f})" if thesis else ""
        print(f"{s:15s} {g:3d} v0 {t['v0']:.2f} s default {t['default']:.2f} s ratio {row['ratio']:.2f}{note}", flush=True)
r = [x["ratio"] for x in rows]
gm = statistics.geometric_mean(r)
summary = {"hbn": hbn, "rows": rows, "geomean_ratio": gm}
print(f"geometric mean ratio {gm:.2f}, max {max(r):.2f}, min {min(r):.2f}, above 3x in {sum(x > 3 for x in r)} "
      f"of {len(r)}; mean default {statistics.mean(x['default'] for x in rows):.2f} s, mean v0 "
      f"{statistics.mean(x['v0'] for x in rows):.2f} s")
if thesis:
    gt = statistics.geometric_mean([x["ratio_thesis"] for x in rows])
    summary["geomean_ratio_thesis"] = gt
    print(f"without the state-only sensor candidate: geometric mean ratio {gt:.2f}, mean "
          f"{statistics.mean(x['thesis'] for x in rows):.2f} s")
json.dump(summary, open(out, "w"), indent=1)
