#!/usr/bin/env python3
"""How much SSIM the measurement allows: the "visible-contact oracle".

For each pair, the true in-contact depth M*D is cut down to the pixels where the object pushes the membrane in by
more than a threshold (penetration E - D > t, E the membrane from the pair's reference, smoothed of its noise) and
scored against the full truth with tnd's SSIM (scikit-image, Gaussian 11-tap window, sigma 1.5, population
covariance, data range 0.1 m). An estimator that knew the depth exactly wherever the press is deeper than t and
nothing elsewhere would score this. The imprint's noise is 1.38 mm per pixel (sigma), so t = 1-2 sigma is about
where single pixels stop being visible; a model can beat the oracle only by inferring the shallow rim from shape
priors.

    python3 assets/validation/ssim_ceiling.py data/real_val/shards/unseen_objects-00000.npz --pairs 0:150

Needs numpy, scipy and scikit-image.
"""
import argparse

import numpy as np
from scipy.ndimage import gaussian_filter
from skimage.metrics import structural_similarity


def ssim(a, b):
    return structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                 data_range=0.1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("shard", help="a dataset shard (.npz with target, mask, reference)")
    ap.add_argument("--pairs", default="0:150", help="START:END of the shard's pairs")
    ap.add_argument("--thresholds-mm", default="0,0.5,1.38,2.76,4", help="penetration thresholds, mm")
    a = ap.parse_args()
    z = np.load(a.shard)
    lo, hi = (int(x) for x in a.pairs.split(":"))
    hi = min(hi, len(z["target"]))
    ts = [float(t) * 1e-3 for t in a.thresholds_mm.split(",")]
    scores = {t: [] for t in ts}
    for i in range(lo, hi):
        depth = z["target"][i].astype(np.float64)
        mask = z["mask"][i] > 0.5
        membrane = gaussian_filter(z["reference"][i].astype(np.float64), 3.0)
        penetration = np.where(mask, membrane - depth, 0.0)
        for t in ts:
            scores[t].append(ssim(np.where(mask & (penetration > t), depth, 0.0), depth))
    print(f"{a.shard}, pairs {lo}-{hi - 1}")
    for t in ts:
        print(f"  truth where penetration > {t * 1e3:4.2f} mm: SSIM {np.mean(scores[t]):.3f}")


if __name__ == "__main__":
    main()
