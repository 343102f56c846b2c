# Each run's exact-GP LML per kernel (docs/data/kernel_evidence_lml_session24.json): python lml.py SYSTEMS GAINS SEEDS OUT.json, with HBN_BIN set
import sys, json, re, subprocess, tempfile, os
sys.path.insert(0, '/work/main/benches/baselines')
os.environ.setdefault('HBN_BIN', '/work/main/target/release/hbn')
import run
systems = sys.argv[1].split(','); gains = [float(g) for g in sys.argv[2].split(',')]; seeds = [int(s) for s in sys.argv[3].split(',')]
out = sys.argv[4]
rows = []
exe = os.environ['HBN_BIN']
for system in systems:
    for gain in gains:
        for seed in seeds:
            with tempfile.TemporaryDirectory() as wd:
                from pathlib import Path; train, test = run.simulate_logs(system, gain, seed, Path(wd), steps=1000)
                row = {'system': system, 'gain': gain, 'seed': seed}
                for kernel in ['matern52', 'se-ard']:
                    args = [exe, 'train']
                    for t in train: args += ['--log', t]
                    args += ['--out', os.path.join(wd, 'm.hbn'), '--inducing', 'exact', '--lags', 'none', '--validation', '0', '--kernel', kernel, '-v', '--seed', str(seed)]
                    p = subprocess.run(args, capture_output=True, text=True)
                    t_lml = re.search(r'transition GP:.*LML\s+(-?[\d.]+)', p.stdout)
                    s_lml = re.search(r'sensor\s+GP:.*LML\s+(-?[\d.]+)', p.stdout)
                    if not (t_lml and s_lml):
                        print(p.stdout, p.stderr, file=sys.stderr); continue
                    row[kernel] = [float(t_lml.group(1)), float(s_lml.group(1))]
                rows.append(row); print(row, flush=True)
json.dump(rows, open(out, 'w'), indent=1)
