"""Session 23's kernel study: the default's model selection with one more candidate, simulated
from two runs' recorded held-out scores (every candidate is scored on the same held-out blocks,
so adding one changes the choice only where it wins).

    python3 docs/data/kernel_study_session23_selection.py docs/data/grid16_default_session23.json \
        docs/data/grid16_se_ard_exact_only_session23.json
"""
import json,sys,math,collections
# usage: sel.py R1.json,R2.json S1.json,S2.json  -> simulated selection with S's config as an extra candidate
def load(fs):
    d={}
    for f in fs.split(','):
        for r in json.load(open(f))['runs']: d[(r['system'],r['gain'],r['seed'])]=r['report']['methods']['hbn']
    return d
R=load(sys.argv[1]); S=load(sys.argv[2])
base='docs/data/baselines_grid16_cv.json'
BS=collections.defaultdict(lambda: collections.defaultdict(list))
for r in json.load(open(base))['runs']:
    for m in ('sk-gp-ekf','lstm'): BS[(r['system'],r['gain'])][m].append(r['report']['methods'][m]['nrmse'])
keys=sorted(set(R)&set(S))
mean=lambda v:sum(v)/len(v)
def pick(k, rule, primary='R'):
    r=R[k]; s=S[k]
    cands=[('R:'+c['config'],c) for c in r['held_out']['candidates']] or [('R:'+r['config'],dict(r['held_out'],chosen=True))]
    sc=s['held_out']['candidates']
    if sc: cands+= [('S:'+c['config'],c) for c in sc]
    else: cands.append(('S:'+s['config'],s['held_out']))
    if primary=='R': prim=[c for n,c in cands if n.startswith('R:') and n.endswith('exact')][0]
    else: prim=[c for n,c in cands if n.startswith('S:') and n.endswith('exact')][0]
    if rule=='acc': el=[(n,c) for n,c in cands if c['nrmse']<=prim['nrmse']]
    elif rule=='any': el=cands
    n,c=min(el,key=lambda t:t[1]['nlpd'])
    if n.startswith('S:'):
        ch=[x for x in sc if x['chosen']] if sc else None
        if sc and n!='S:'+[x for x in sc if x['chosen']][0]['config']: return n, None
        return n, s
    else:
        if r['held_out']['candidates'] and n!='R:'+[x for x in r['held_out']['candidates'] if x['chosen']][0]['config']: return n,None
        return n, r
for rule,prim in (('acc','R'),('acc','S'),('any','R')):
    res={};names=collections.Counter();miss=0
    for k in keys:
        n,m=pick(k,rule,prim)
        if m is None: miss+=1; m=R[k]
        res[k]=m; names[n]+=1
    cells=sorted(set(k[:2] for k in keys))
    lr=[];lb=[];cov=0;nees=0;le=0
    for c in cells:
        ks=[k for k in keys if k[:2]==c]
        e=mean([res[k]['nrmse'] for k in ks]); er=mean([R[k]['nrmse'] for k in ks])
        bb=min(mean(BS[c]['sk-gp-ekf']),mean(BS[c]['lstm']))
        lr.append(math.log(e/er)); lb.append(math.log(e/bb)); le+=e/bb<=0.8
        cv=mean([res[k]['coverage_2sigma'] for k in ks]); ne=mean([res[k]['mean_nees'] for k in ks])
        cov+=0.9<=cv<=0.98; nees+=0.5<=ne<=2
        if rule=='acc' and prim=='R': print(f"  {c[0][:12]:12s} g{c[1]:<4} {e:.4f} vs R {er:.4f} ({e/er:.2f}x) base {e/bb:.2f}x cov {cv:.3f} nees {ne:.2f}")
    print(f"rule {rule} primary {prim}: vs R {math.exp(mean(lr)):.3f}, vs better baseline {math.exp(mean(lb)):.3f}, <=0.8 in {le}, cov {cov}/16 nees {nees}/16; picks {dict(names)}; unresolved {miss}")
