"""Per-cell comparison of hbn's default between two judged-grid runs of
`benches/baselines/run.py`, with calibration counts and the ratio to the better baseline.

usage: python3 docs/data/grid_cells_compare_session26.py OLD.json[,OLD2.json] NEW.json[,NEW2.json] [BASELINES.json]

Prints the geometric mean of NEW / OLD nRMSE over the runs both have, then per cell (system,
gain; mean over seeds) nRMSE, 2-sigma coverage and mean NEES, old -> new, the number of cells
whose coverage is in [0.90, 0.98] and whose mean NEES is in [0.5, 2], and, with BASELINES (a
grid run that has the `sk-gp-ekf` and `lstm` methods), the geometric mean over the cells of
hbn's nRMSE over the better baseline's, the number of cells at most 0.8x, and that geometric
mean per noise gain. Several files, comma-separated, are merged (one grid run split over two
processes). One grid run given three times (OLD, NEW and BASELINES) scores that run alone."""
import json, math, sys, collections
def load(paths):
    out={}
    for p in paths.split(','):
        for r in json.load(open(p))["runs"]:
            out[(r["system"], r["gain"], r["seed"])]=r["report"]["methods"]
    return out
old=load(sys.argv[1]); new=load(sys.argv[2])
base=load(sys.argv[3]) if len(sys.argv)>3 else {}
keys=sorted(set(old)&set(new))
logs=[math.log(new[k]["hbn"]["nrmse"]/old[k]["hbn"]["nrmse"]) for k in keys]
print(f"runs {len(keys)} per-run geomean new/old {math.exp(sum(logs)/len(logs)):.4f}, better in {sum(l<-1e-12 for l in logs)}, worse in {sum(l>1e-12 for l in logs)}")
cells=collections.defaultdict(list)
for k in keys: cells[k[:2]].append(k)
inb=lambda c,n:(0.9<=c<=0.98, 0.5<=n<=2)
cnt=[0,0,0,0]; rb_o=[]; rb_n=[]; by_gain=collections.defaultdict(list)
for c,ks in sorted(cells.items()):
    f=lambda d,m: sum(d[k]["hbn"][m] for k in ks)/len(ks)
    no,nn=f(old,"nrmse"),f(new,"nrmse"); co,cn=f(old,"coverage_2sigma"),f(new,"coverage_2sigma"); eo,en=f(old,"mean_nees"),f(new,"mean_nees")
    a=inb(co,eo); b=inb(cn,en); cnt[0]+=a[0];cnt[1]+=a[1];cnt[2]+=b[0];cnt[3]+=b[1]
    bb=""
    if base and all(k in base for k in ks):
        best=min(sum(base[k][m]["nrmse"] for k in ks)/len(ks) for m in ("sk-gp-ekf","lstm") if m in base[ks[0]])
        rb_o.append(math.log(no/best)); rb_n.append(math.log(nn/best)); by_gain[c[1]].append(math.log(nn/best)); bb=f" vs best {no/best:.2f}->{nn/best:.2f}"
    print(f"{c[0]:14s} {c[1]:4} nrmse {no:.4f}->{nn:.4f} ({nn/no:.2f}) cov2 {co:.3f}->{cn:.3f} nees {eo:.2f}->{en:.2f}{bb}")
print(f"cov in band old {cnt[0]} new {cnt[2]}; nees in band old {cnt[1]} new {cnt[3]} of {len(cells)}")
if rb_o: print(f"vs better baseline geomean old {math.exp(sum(rb_o)/len(rb_o)):.3f} new {math.exp(sum(rb_n)/len(rb_n)):.3f}; <=0.8 old {sum(x<=math.log(0.8) for x in rb_o)} new {sum(x<=math.log(0.8) for x in rb_n)}")
for g,v in sorted(by_gain.items()): print(f"  new vs better baseline at gain {g:g}: geomean {math.exp(sum(v)/len(v)):.3f} over {len(v)} cells")
