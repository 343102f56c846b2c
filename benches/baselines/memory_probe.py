"""Play operators (docs/memory.md) outside hbn: the scikit-learn GP-EKF baseline of
``gp_ekf.py`` with play-operator outputs of ``u`` added to its transition GP's inputs, against
the same baseline without them, on one simulated cell (``run.simulate_logs``: three training
logs, one test log with another input, never used in training). Prints one JSON line: the test
nRMSE without plays (``base``) and with each set of radii.

    python benches/baselines/memory_probe.py SYSTEM GAIN SEED [--workdir DIR]

Every play starts at the first training input; radii are fractions of the training input's
range. It is a probe, not a baseline, and keeps its own copy of the numpy EKF loop (with the
extra inputs) for that reason.
"""
import argparse
import json
import math
import sys
import tempfile
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy as np
import common, gp_ekf, run as R

def plays(u, radii, p0):
    """play outputs of u (causal): P[k, j] = play_j after u_0..u_k"""
    P = np.zeros((len(u), len(radii)))
    p = np.array([p0]*len(radii), dtype=float)
    for k, v in enumerate(u):
        for j, r in enumerate(radii):
            p[j] = max(v - r, min(v + r, p[j]))
        P[k] = p
    return P

def feats(lg, radii, umid):
    return plays(lg.u, radii, umid)

def trows(logs, radii, umid):
    X, t = [], []
    for lg in logs:
        P = feats(lg, radii, umid)
        X.append(np.column_stack([lg.x[1:-1], lg.x[:-2], lg.u[1:-1], lg.u[:-2], P[1:-1]]))
        t.append(lg.x[2:])
    return np.vstack(X), np.concatenate(t)

def estimate(model, gd, u, y, radii, umid):
    n = len(u)
    x_hat, x_std = np.full(n, np.nan), np.full(n, np.nan)
    R_ = model.sensor.noise_var
    y0 = float(y[0]); m0, v0 = gp_ekf.initial_x(model, y0)
    z = np.array([m0, m0, y0]); P = np.array([[v0, v0, 0.0], [v0, v0, 0.0], [0.0, 0.0, R_]])
    x_hat[0], x_std[0] = z[0], math.sqrt(P[0, 0]); H = np.array([0.0, 0.0, 1.0])
    PL = plays(u, radii, umid)
    for k in range(1, n):
        u1, u2 = u[k - 1], u[k - 2] if k >= 2 else u[0]
        f_ = PL[k-1] if k >= 1 else PL[0]
        mx, vx, gx = gd.predict(np.concatenate([[z[0], z[1], u1, u2], f_]))
        ms, vs, gs = model.sensor.predict(np.array([z[0], z[2], mx]))
        a1, a2 = gx[0], gx[1]; c, e, f = gs
        F = np.array([[a1, a2, 0.0], [1.0, 0.0, 0.0], [c + f * a1, f * a2, e]])
        G = np.array([1.0, 0.0, f])
        Q = np.outer(G, G) * (vx + gd.noise_var) + np.diag([0.0, 0.0, vs])
        z = np.array([mx, z[0], ms]); P = F @ P @ F.T + Q
        S = P[2, 2] + R_
        if np.isfinite(y[k]) and S > 0.0:
            K = P[:, 2] / S; z = z + K * (y[k] - z[2])
            IKH = np.eye(3) - np.outer(K, H); P = IKH @ P @ IKH.T + R_ * np.outer(K, K)
        P = 0.5 * (P + P.T)
        x_hat[k], x_std[k] = z[0], math.sqrt(max(P[0, 0], 0.0))
    return x_hat, x_std

def main(system, gain, seed, fracs, workdir=None):
    with tempfile.TemporaryDirectory(prefix="hbn-memory-probe-") as tmp:
        wd = Path(workdir or tmp) / f"{system}_{gain}_{seed}"
        tr, te = R.simulate_logs(system, gain, seed, wd)
        logs = [common.read_log(p, common.DEFAULT_PATHS) for p in tr]
        test = common.read_log(te, common.DEFAULT_PATHS)
    us = np.concatenate([l.u for l in logs]); span = float(np.ptp(us)); umid = float(us[0])
    base = gp_ekf.fit(logs, seed=seed)
    out = {}
    x, s = gp_ekf.estimate(base, test.u, test.y)
    out["base"] = common.score(x, s, test.x)["nrmse"]
    for fr in fracs:
        radii = [f * span for f in fr]
        rng = np.random.default_rng(seed)
        Xd, td = common.subsample(*trows(logs, radii, umid), gp_ekf.GP_ROWS, rng)
        gd = gp_ekf.SkGP(1, seed).fit(Xd, td)
        x, s = estimate(base, gd, test.u, test.y, radii, umid)
        out[str(fr)] = common.score(x, s, test.x)["nrmse"]
    print(json.dumps({"system": system, "gain": gain, "seed": seed, **out}), flush=True)

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("system")
    ap.add_argument("gain", type=float)
    ap.add_argument("seed", type=int)
    ap.add_argument("--workdir", default=None, help="keep the simulated logs here (default: a temporary directory)")
    a = ap.parse_args()
    main(a.system, a.gain, a.seed, [[0.05], [0.15], [0.05, 0.2]], a.workdir)
