"""Baseline 2: a causal LSTM from ``(u_k, y_k)`` to ``x_k`` (torch on CPU; optional).

A 2-layer LSTM (hidden 32) with a linear head reads the standardised sequence ``(u_k, y_k)``
and outputs the standardised ``x_k``; being unidirectional and run forward from a zero state
over the whole test log, its output at ``k`` depends on ``u_0..u_k, y_0..y_k`` only.

Training (all from the training logs; the test log is never seen):

* signals standardised with the mean and standard deviation of the training part;
* the last 20% of EVERY training log is held out for early stopping (under the thesis'
  protocol the training logs repeat one input, so holding out a whole log would validate on an
  input already trained on; the tail of each log is an input segment never trained on);
* truncated BPTT: random windows of ``window`` samples from the training parts, each started
  from a zero state, the loss (MSE) taken after a ``burn_in`` of samples so the state has
  warmed up; Adam with a cosine decay of the learning rate to 10%; at most ``max_steps``
  updates;
* every ``eval_every`` updates the model is run causally over each held-out tail (warmed up on
  the training part just before it, as at run time the state has seen the whole past) and
  the best weights by validation MSE are kept; training stops after ``patience`` evaluations
  without improvement.

Everything is seeded; ``torch.set_num_threads(1)``. When torch is not installed,
:func:`available` is False and :data:`SKIP_NOTICE` says so; callers skip the method.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from common import Log

#: What callers print when torch is missing.
SKIP_NOTICE = "LSTM skipped: torch not installed (pip install torch)"


def available() -> bool:
    """True when ``import torch`` works."""
    try:
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class LstmConfig:
    """Size and training settings of the LSTM baseline."""

    hidden: int = 32
    layers: int = 2
    window: int = 64
    burn_in: int = 16
    batch: int = 16
    lr: float = 5e-3
    max_steps: int = 1200
    eval_every: int = 40
    patience: int = 10
    val_fraction: float = 0.2


def _split(logs: Sequence[Log], val_fraction: float) -> Tuple[List[Tuple[np.ndarray, np.ndarray]], List[Tuple[int, np.ndarray, np.ndarray]]]:
    """Training parts ``(features, target)`` and validation tails ``(offset, features,
    target)`` (raw units) of every log: the last ``val_fraction`` of each log is validation."""
    train, val = [], []
    for lg in logs:
        n = len(lg)
        cut = int(round(n * (1.0 - val_fraction)))
        feats = np.column_stack([lg.u, lg.y])
        train.append((feats[:cut], lg.x[:cut]))
        if n - cut >= 2:
            val.append((cut, feats, lg.x))
    return train, val


def run(
    train: Sequence[Log], test: Log, seed: int = 0, config: Optional[LstmConfig] = None
) -> Dict[str, Any]:
    """Trains the LSTM on ``train`` and predicts ``x`` causally on ``test``.

    Returns ``x`` (no standard deviation: ``x_std`` is None), ``train_seconds``,
    ``estimate_seconds``, ``steps`` (updates made), ``best_val_mse`` (standardised units) and
    ``val_history`` (``(update, validation MSE)`` pairs) and ``config``. Raises ``ImportError`` when torch is missing (check :func:`available`).
    """
    import torch
    from torch import nn

    cfg = config or LstmConfig()
    t0 = time.perf_counter()
    torch.set_num_threads(1)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)

    parts, vals = _split(train, cfg.val_fraction)
    f_all = np.vstack([f for f, _ in parts])
    x_all = np.concatenate([x for _, x in parts])
    ok = np.all(np.isfinite(f_all), axis=1) & np.isfinite(x_all)
    f_mu, f_sd = f_all[ok].mean(axis=0), f_all[ok].std(axis=0)
    f_sd = np.where(f_sd > 0, f_sd, 1.0)
    x_mu, x_sd = float(x_all[ok].mean()), float(x_all[ok].std()) or 1.0

    def norm_f(f: np.ndarray) -> np.ndarray:
        # Standardise; a missing sample (NaN) becomes the mean (0), as a held input would.
        return np.nan_to_num((f - f_mu) / f_sd, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)

    class Net(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.lstm = nn.LSTM(2, cfg.hidden, num_layers=cfg.layers, batch_first=True)
            self.head = nn.Linear(cfg.hidden, 1)

        def forward(self, f: "torch.Tensor") -> "torch.Tensor":
            h, _ = self.lstm(f)
            return self.head(h).squeeze(-1)

    net = Net()
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    # Cosine decay of the learning rate to 10% over max_steps.
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda i: 0.1 + 0.45 * (1.0 + math.cos(math.pi * min(i, cfg.max_steps) / cfg.max_steps))
    )
    seqs = [(norm_f(f), ((x - x_mu) / x_sd).astype(np.float32)) for f, x in parts]
    starts = [(i, s) for i, (f, _) in enumerate(seqs) for s in range(0, max(1, len(f) - cfg.window + 1))]
    if not starts:
        raise ValueError("the training logs are too short for the LSTM")
    val_in = [(torch.from_numpy(norm_f(f))[None], off, (x - x_mu) / x_sd) for off, f, x in vals]

    def val_mse() -> float:
        net.eval()
        with torch.no_grad():
            errs = []
            for f, off, x in val_in:
                p = net(f)[0].numpy()
                e = (p[off:] - x[off:])
                errs.append(e[np.isfinite(e)])
        net.train()
        return float(np.mean(np.concatenate(errs) ** 2)) if errs else float("nan")

    best, best_state, bad, step = float("inf"), None, 0, 0
    history: List[Tuple[int, float]] = []
    for step in range(1, cfg.max_steps + 1):
        pick = rng.integers(0, len(starts), size=cfg.batch)
        fb = np.stack([seqs[starts[j][0]][0][starts[j][1] : starts[j][1] + cfg.window] for j in pick])
        xb = np.stack([seqs[starts[j][0]][1][starts[j][1] : starts[j][1] + cfg.window] for j in pick])
        pred = net(torch.from_numpy(fb))[:, cfg.burn_in :]
        tgt = torch.from_numpy(xb)[:, cfg.burn_in :]
        mask = torch.isfinite(tgt)
        loss = ((pred - torch.nan_to_num(tgt)) ** 2)[mask].mean()
        opt.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        sched.step()
        if step % cfg.eval_every == 0 or step == cfg.max_steps:
            if not val_in:
                continue
            v = val_mse()
            history.append((step, v))
            if v < best:
                best, bad = v, 0
                best_state = {k: t.detach().clone() for k, t in net.state_dict().items()}
            else:
                bad += 1
                if bad >= cfg.patience:
                    break
    if best_state is not None:
        net.load_state_dict(best_state)
    t1 = time.perf_counter()
    net.eval()
    with torch.no_grad():
        p = net(torch.from_numpy(norm_f(np.column_stack([test.u, test.y])))[None])[0].numpy()
    x_hat = p.astype(np.float64) * x_sd + x_mu
    t2 = time.perf_counter()
    return {
        "x": x_hat,
        "x_std": None,
        "train_seconds": t1 - t0,
        "estimate_seconds": t2 - t1,
        "steps": step,
        "best_val_mse": best if best_state is not None else None,
        "val_history": history,
        "config": dataclasses.asdict(cfg),
    }
