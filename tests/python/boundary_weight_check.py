#!/usr/bin/env python3
"""train_torch.py's contact-boundary loss weights (`--boundary-weight`) against two independent truths: the hand-made
case that src/model/train_data.rs's unit test checks tnd's own weights with (a 4 x 4 contact in an 8 x 8 image:
weight 1.5 on the 32-pixel ring either side of its edge, 0.5 elsewhere), and a plain loop over random masks, images
without contact and all-contact images included. Run by .ci/run; exits 1 with a message on a mismatch."""
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "assets" / "models" / "gpu"))
from train_torch import boundary_weights  # noqa: E402


def by_loop(target, r, weight):
    n, _, h, w = target.shape
    out = np.ones_like(target)
    for i in range(n):
        contact = target[i, 0] > 0.005
        for y in range(h):
            for x in range(w):
                win = contact[max(0, y - r):y + r + 1, max(0, x - r):x + r + 1]
                if win.any() and not win.all():
                    out[i, 0, y, x] = 1.0 + weight
        out[i, 0] /= out[i, 0].mean()
    return out


def main():
    t = np.zeros((1, 1, 8, 8), np.float32)
    t[0, 0, 2:6, 2:6] = 0.04
    got = boundary_weights(torch.from_numpy(t), 1, 2.0).numpy()[0, 0]
    ring = np.zeros((8, 8), bool)
    ring[1:7, 1:7] = True
    ring[3:5, 3:5] = False
    want = np.where(ring, 1.5, 0.5)
    if not np.array_equal(got, want):
        sys.exit(f"boundary weights of the 4 x 4 square:\n{got}\nexpected\n{want}")
    rng = np.random.default_rng(0)
    target = np.where(rng.random((6, 1, 16, 12)) < 0.4, rng.uniform(0.03, 0.09, (6, 1, 16, 12)), 0.0)
    target[4] = 0.0
    target[5] = 0.06
    target = target.astype(np.float32)
    for r, weight in [(1, 2.0), (2, 4.0), (3, 0.5)]:
        got = boundary_weights(torch.from_numpy(target), r, weight).numpy()
        want = by_loop(target, r, weight)
        err = np.abs(got - want).max()
        if err > 1e-6:
            sys.exit(f"boundary weights, radius {r}, weight {weight}: max difference {err} from the loop")
    print("boundary weights: the hand-made ring and 18 random images match")


if __name__ == "__main__":
    main()
