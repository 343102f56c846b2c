"""Probe: the scikit-learn GP-EKF baseline with the HBN sensor [x_{k-1}, s_{k-1}, x_k] -> y_k
against a sensor without the previous output, [x_{k-1}, x_k] -> y_k (the level of x observable
from y directly). Same rows, same transition GP, same EKF otherwise."""
import math, sys, tempfile, json
from pathlib import Path
import numpy as np
sys.path.insert(0, "/work/main/benches/baselines")
import common, gp_ekf, run
from gp_ekf import SkGP, initial_x

def fit_level(logs, seed=0, rows=600):
    rng = np.random.default_rng(seed)
    Xd, td = common.subsample(*common.transition_rows(logs), rows, rng)
    Xs, ts = common.subsample(*common.sensor_rows(logs), rows, rng)
    gd = SkGP(1, seed).fit(Xd, td)
    gs = SkGP(1, seed + 1).fit(Xs[:, [0, 2]], ts)
    ys = np.concatenate([lg.y for lg in logs]); xs = np.concatenate([lg.x for lg in logs])
    return gp_ekf.GpEkfModel(gd, gs, ys, xs, float(np.ptp(xs)))

def estimate_level(model, u, y):
    n = len(u); x_hat = np.full(n, np.nan); x_std = np.full(n, np.nan)
    R = model.sensor.noise_var
    m0, v0 = initial_x(model, float(y[0]))
    z = np.array([m0, m0]); P = np.array([[v0, v0], [v0, v0]])
    x_hat[0], x_std[0] = z[0], math.sqrt(P[0, 0])
    for k in range(1, n):
        u1, u2 = u[k - 1], u[k - 2] if k >= 2 else u[0]
        mx, vx, gx = model.transition.predict(np.array([z[0], z[1], u1, u2]))
        a1, a2 = gx[0], gx[1]
        F = np.array([[a1, a2], [1.0, 0.0]])
        Qx = vx + model.transition.noise_var
        P = F @ P @ F.T + np.diag([Qx, 0.0])
        zp = np.array([mx, z[0]])
        ms, vs, gs = model.sensor.predict(np.array([zp[1], zp[0]]))
        H = np.array([gs[1], gs[0]])
        S = H @ P @ H + R + vs
        if np.isfinite(y[k]) and S > 0:
            K = P @ H / S
            zp = zp + K * (y[k] - ms)
            IKH = np.eye(2) - np.outer(K, H)
            P = IKH @ P @ IKH.T + (R + vs) * np.outer(K, K)
        P = 0.5 * (P + P.T); z = zp
        x_hat[k], x_std[k] = z[0], math.sqrt(max(P[0, 0], 0.0))
    return x_hat, x_std

systems = sys.argv[1].split(","); gains = [float(g) for g in sys.argv[2].split(",")]; seeds = [int(s) for s in sys.argv[3].split(",")]
for system in systems:
    for gain in gains:
        for seed in seeds:
            with tempfile.TemporaryDirectory() as wd:
                tr, te = run.simulate_logs(system, gain, seed, Path(wd))
                train, test = common.read_logs(tr, te, common.DEFAULT_PATHS)
            base = gp_ekf.run(train, test, seed=seed)
            m = fit_level(train, seed=seed)
            xl, sl = estimate_level(m, test.u, test.y)
            sb = common.score(base["x"], base["x_std"], test.x); sc = common.score(xl, sl, test.x)
            print(json.dumps({"system": system, "gain": gain, "seed": seed, "hbn_sensor": sb["nrmse"], "level_sensor": sc["nrmse"],
                              "cov_hbn": sb["coverage_2sigma"], "cov_level": sc["coverage_2sigma"]}), flush=True)
