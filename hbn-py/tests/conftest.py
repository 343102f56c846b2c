"""Shared fixtures of the hbn Python tests."""

import os
import pathlib
import sys

import numpy as np
import pytest

import hbn

REPO = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benches"))


def nrmse(est, ref):
    ref = np.asarray(ref)
    return float(np.sqrt(np.mean((np.asarray(est) - ref) ** 2)) / (ref.max() - ref.min()))


@pytest.fixture(scope="session")
def repo():
    return REPO


@pytest.fixture(scope="session")
def trained():
    """A small model of the Duhem system and a fresh test trajectory."""
    train = hbn.simulate("duhem", 600, seed=1, noise_gain=1.0)
    model = hbn.HysteresisModel.fit(
        train["u"], train["x"], train["y"], max_points=250, n_starts=1, seed=0
    )
    test = hbn.simulate("duhem", 500, seed=2, noise_gain=1.0)
    return model, train, test


def find_hbn_bin():
    """The CLI binary: $HBN_BIN, else target/release/hbn, else target/debug/hbn, else None."""
    env = os.environ.get("HBN_BIN")
    if env:
        return env
    for p in (REPO / "target" / "release" / "hbn", REPO / "target" / "debug" / "hbn"):
        if p.is_file() and os.access(p, os.X_OK):
            return str(p)
    return None
