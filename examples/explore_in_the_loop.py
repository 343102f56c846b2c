"""Exploration with a robot in the loop (thesis Sec. 3.4), a simulator standing in for the robot.

Drives hbn.Simulator with hbn.Explorer for --samples samples, trains the default model on what
it collected, trains the same model on as many samples of random-ramp input (what
hbn.simulate generates), and scores both on a fresh random-ramp test run that neither saw.
Prints both nRMSE values and checks that no proposal broke the input bounds or the increment
bound. Needs only numpy and the hbn wheel.

    python examples/explore_in_the_loop.py --system bouc-wen --samples 1000 --seed 1

docs/exploration.md explains the explorer's schedule and when it pays.
"""

import argparse

import numpy as np

import hbn

U_MIN, U_MAX, MAX_STEP = 0.0, 1.0, 0.02


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--system", default="bouc-wen", choices=hbn.SYSTEMS)
    ap.add_argument("--samples", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--noise-gain", type=float, default=1.0)
    ap.add_argument("--test-samples", type=int, default=1500)
    args = ap.parse_args()

    # The robot in the loop: propose an input, apply it, give back what was measured.
    explorer = hbn.Explorer(U_MIN, U_MAX, MAX_STEP, rate_hz=100.0, seed=args.seed)
    robot = hbn.Simulator(args.system, seed=args.seed, noise_gain=args.noise_gain)
    applied = []
    for _ in range(args.samples):
        u = explorer.propose()
        x, y = robot.step(u)
        explorer.observe(u, x, y)
        applied.append(u)
    u = np.asarray(applied)
    in_bounds = bool(np.all((u >= U_MIN) & (u <= U_MAX)))
    steps_ok = bool(np.all(np.abs(np.diff(u)) <= MAX_STEP))
    explored = explorer.model()

    # The same amount of random-ramp data.
    rnd = hbn.simulate(args.system, args.samples, seed=args.seed, noise_gain=args.noise_gain)
    random_model = hbn.HysteresisModel.fit(rnd["u"], rnd["x"], rnd["y"], rate_hz=100.0)

    test = hbn.simulate(args.system, args.test_samples, seed=1000 + args.seed, noise_gain=args.noise_gain)
    scores = {}
    for name, model in [("explorer", explored), ("random ramps", random_model)]:
        est = model.estimate(test["u"], test["y"])
        scores[name] = est.score(test["x"])["nrmse"]
    print(f"{args.system}, {args.samples} samples, seed {args.seed}, noise gain {args.noise_gain}")
    print(f"  input range visited by the explorer: [{u.min():.3f}, {u.max():.3f}]")
    print(f"  bounds kept: {in_bounds}; increment bound kept: {steps_ok}")
    for name, v in scores.items():
        print(f"  nRMSE {name}: {v:.4f}")
    print(f"  ratio explorer / random ramps: {scores['explorer'] / scores['random ramps']:.2f}")
    if not (in_bounds and steps_ok):
        raise SystemExit("the explorer broke a bound")


if __name__ == "__main__":
    main()
