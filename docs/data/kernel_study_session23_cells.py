"""Session 23's kernel study: cell means of several grid runs side by side, against the
baselines of docs/data/baselines_grid16_cv.json (the better of their cell means).

    python3 docs/data/kernel_study_session23_cells.py R=docs/data/grid16_default_session23.json \
        se-ard=docs/data/grid16_se_ard_session23.json
"""
import json,sys,collections,math
# usage: cmp2.py name=file1,file2 name2=file3 ...   (first is the reference)
base='docs/data/baselines_grid16_cv.json'
BS=collections.defaultdict(lambda: collections.defaultdict(list))
for r in json.load(open(base))['runs']:
    for m in ('sk-gp-ekf','lstm'): BS[(r['system'],r['gain'])][m].append(r['report']['methods'][m]['nrmse'])
names=[];D=[]
for a in sys.argv[1:]:
    n,fs=a.split('=');names.append(n);d={}
    for f in fs.split(','):
        for r in json.load(open(f))['runs']: d[(r['system'],r['gain'],r['seed'])]=r['report']['methods']['hbn']
    D.append(d)
keys=sorted(set.intersection(*[set(d) for d in D]))
cells=sorted(set(k[:2] for k in keys))
mean=lambda v:sum(v)/len(v)
print("cell".ljust(20)+"".join(f"{n:>28s}" for n in names))
stats=[[0,0,0,[],[]] for _ in names]
for c in cells:
    ks=[k for k in keys if k[:2]==c]; bb=min(mean(BS[c]['sk-gp-ekf']),mean(BS[c]['lstm'])) if c in BS else float('nan')
    row=f"{c[0][:12]} g{c[1]:<4}".ljust(20)
    for i,d in enumerate(D):
        e=mean([d[k]['nrmse'] for k in ks]); cv=mean([d[k]['coverage_2sigma'] for k in ks]); ne=mean([d[k]['mean_nees'] for k in ks])
        r=e/bb; s=stats[i]; s[0]+=0.9<=cv<=0.98; s[1]+=0.5<=ne<=2; s[2]+=r<=0.8; s[3].append(math.log(r)); s[4].append(math.log(e))
        row+=f"  {e:.4f} {r:5.2f}x c{cv:.3f} e{ne:5.2f}"
    print(row)
for n,s in zip(names,stats):
    print(f"{n}: geo vs better baseline {math.exp(mean(s[3])):.3f}, <=0.8x in {s[2]}, cov in band {s[0]}/{len(cells)}, nees in band {s[1]}/{len(cells)}, geo nrmse vs first {math.exp(mean(s[4])-mean(stats[0][4])):.3f}")
