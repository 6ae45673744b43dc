#!/usr/bin/env python3
"""Where a model's SSIM goes: mask against depth, clean-ups, and what choosing among its samples could reach.

Reads the samples `tnd eval --save-samples DIR` kept (one .npz per pair: target, samples, ...) and scores, with
tnd's SSIM (scikit-image, Gaussian 11-tap window, sigma 1.5, population covariance, data range 0.1 m):

* the first sample (what `tnd eval`'s single-sample rows score) and the mean over all samples;
* two oracles that put the truth back into one part: the true contact mask filled with the sample's depths (what a
  perfect mask would give), and the sample's mask filled with the true depths (what perfect depths would give);
* mask clean-ups of the first sample: dropping small islands, keeping the largest, filling small holes, a 3x3
  median, an opening, one pixel of dilation or erosion;
* with N > 1 samples: the per-pixel majority (contact where at least half of the samples say so, at their median
  depth: `tnd eval`'s consensus) and the best single sample chosen with the truth (an upper bound for any rule
  that picks one of the N);
* missed and invented contact pixels, split by whether they lie within one pixel of the other mask's edge.

    tnd eval --data data/real_val --split unseen_objects --limit 150 --pose-samples 8 --save-samples out/val8
    python3 assets/validation/mask_errors.py out/val8/unseen_objects

Needs numpy, scipy and scikit-image.
"""
import argparse
import glob
import os
import warnings

import numpy as np
from scipy import ndimage as ndi
from skimage.metrics import structural_similarity


def ssim(a, b):
    return structural_similarity(a.astype(np.float64), b.astype(np.float64), gaussian_weights=True, sigma=1.5,
                                 use_sample_covariance=False, data_range=0.1)


def drop_small(x, k):
    """Zero the contact islands (4-connected) smaller than k pixels."""
    lab, n = ndi.label(x > 0)
    if n == 0:
        return x
    sizes = ndi.sum(x > 0, lab, range(1, n + 1))
    small = np.isin(lab, 1 + np.flatnonzero(sizes < k))
    return np.where(small, 0, x)


def largest(x):
    lab, n = ndi.label(x > 0)
    if n <= 1:
        return x
    sizes = ndi.sum(x > 0, lab, range(1, n + 1))
    return np.where(lab == 1 + np.argmax(sizes), x, 0)


def fill_holes(x, k):
    """Fill holes smaller than k pixels with the median depth of their rim."""
    m = x > 0
    lab, n = ndi.label(ndi.binary_fill_holes(m) & ~m)
    y = x.copy()
    for j in range(1, n + 1):
        hole = lab == j
        if hole.sum() < k:
            y[hole] = np.median(x[ndi.binary_dilation(hole) & m])
    return y


def dilate(x):
    m = x > 0
    if not m.any():
        return x
    idx = ndi.distance_transform_edt(~m, return_distances=False, return_indices=True)
    grown = ndi.binary_dilation(m, structure=ndi.generate_binary_structure(2, 1))
    return np.where(grown, np.where(m, x, x[idx[0], idx[1]]), 0)


def consensus(samples):
    """Contact where at least half of the samples say so, at their median depth there."""
    votes = (samples > 0).mean(0) >= 0.5
    depths = np.where(samples > 0, samples, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: no contact there, filled below
        med = np.nanmedian(np.where(votes[None], depths, np.nan), 0)
    return np.where(votes, np.nan_to_num(med), 0)


def within_one(mask, other):
    """Pixels of `mask` within one pixel (8-neighbourhood) of `other`."""
    return mask & ndi.binary_dilation(other, structure=np.ones((3, 3)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dir", help="a folder of tnd eval --save-samples .npz files (one split)")
    a = ap.parse_args()
    files = sorted(glob.glob(os.path.join(a.dir, "*.npz")), key=lambda f: int(os.path.basename(f)[:-4]))
    if not files:
        raise SystemExit(f"{a.dir}: no .npz files")
    rows = {}

    def add(k, v):
        rows.setdefault(k, []).append(v)

    for f in files:
        z = np.load(f)
        t, samples = z["target"], z["samples"]
        x = samples[0]
        mt, mx = t > 0, x > 0
        add("first sample", ssim(x, t))
        add("mean over samples", np.mean([ssim(s, t) for s in samples]))
        fill = np.median(x[mx]) if mx.any() else 0.08
        add("oracle: true mask, sample depths", ssim(np.where(mt, np.where(mx, x, fill), 0), t))
        tfill = np.median(t[mt]) if mt.any() else 0.08
        add("oracle: sample mask, true depths", ssim(np.where(mx, np.where(mt, t, tfill), 0), t))
        for k in (3, 12, 25):
            add(f"drop islands < {k} px", ssim(drop_small(x, k), t))
        add("largest island only", ssim(largest(x), t))
        add("fill holes < 10 px", ssim(fill_holes(x, 10), t))
        add("3x3 median", ssim(ndi.median_filter(x, 3, mode="nearest"), t))
        add("opening", ssim(np.where(ndi.binary_opening(mx), x, 0), t))
        add("dilate 1 px", ssim(dilate(x), t))
        add("erode 1 px", ssim(np.where(ndi.binary_erosion(mx), x, 0), t))
        if len(samples) > 1:
            add(f"consensus of {len(samples)}", ssim(consensus(samples), t))
            add(f"best of {len(samples)} (chosen with the truth)", max(ssim(s, t) for s in samples))
        add("px true", mt.sum())
        add("px sample", mx.sum())
        add("px missed, within 1 px of the sample's edge", within_one(mt & ~mx, mx).sum())
        add("px missed, further", (mt & ~mx).sum() - within_one(mt & ~mx, mx).sum())
        add("px invented, within 1 px of the true edge", within_one(mx & ~mt, mt).sum())
        add("px invented, further", (mx & ~mt).sum() - within_one(mx & ~mt, mt).sum())
    base = np.array(rows["first sample"])
    print(f"{len(files)} pairs of {a.dir}")
    print("| | mean | paired difference to the first sample |\n| --- | --- | --- |")
    for k, v in rows.items():
        v = np.array(v, dtype=np.float64)
        if k.startswith("px"):
            print(f"| {k} | {v.mean():.1f} | |")
        else:
            d = v - base
            print(f"| {k} | {v.mean():.4f} | {d.mean():+.4f} ± {d.std(ddof=1) / np.sqrt(len(d)):.4f} |")


if __name__ == "__main__":
    main()
