# Per-run geometric mean of nRMSE ratios against a base grid: python3 kernel_evidence_session24_perrun.py BASE.json OTHER.json ...
import json, math, sys
def load(f):
    return {(r['system'],r['gain'],r['seed']): r['report']['methods']['hbn'] for r in json.load(open(f))['runs']}
base=load(sys.argv[1])
for f in sys.argv[2:]:
    o=load(f); ks=[k for k in o if k in base]
    l=[math.log(o[k]['nrmse']/base[k]['nrmse']) for k in ks]
    nf=[math.log(o[k]['nrmse']/base[k]['nrmse']) for k in ks if k[1]==0]
    nn=[math.log(o[k]['nrmse']/base[k]['nrmse']) for k in ks if k[1]!=0]
    better=sum(1 for x in l if x<0)
    print(f.split('/')[-2] if 'grid.json' in f else f.split('/')[-1], 'runs',len(l),'per run %.3f'%math.exp(sum(l)/len(l)), 'better in',better, 'noise-free %.3f'%math.exp(sum(nf)/max(1,len(nf))), 'noisy %.3f'%math.exp(sum(nn)/max(1,len(nn))))
