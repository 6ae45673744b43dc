#!/usr/bin/env python3
"""Compare two models on the same pairs: paired differences of two `tnd eval --records` files.

    python3 assets/validation/compare_records.py A.jsonl B.jsonl [--json]

A and B are the records of `tnd eval ... --records FILE` for the same dataset, split, limit and seed with two models
(e.g. the shipped default and a candidate), ideally from the same binary. Pairs are matched by (split, index); the
files must hold the same pairs of the same objects, or the script refuses. Printed per metric: the mean of A and of
B, and the mean paired difference B − A with its standard error (standard deviation of the differences / √n) — a
difference within ~2 standard errors is not established. Metrics: the sample's SSIM and L1 (`model.depth`), the
pipeline's position error (`model_combined`, what `tnd pose` reports; mean and median) and θ error, the sample-only
position error (`model`), and the baselines' position errors (the threshold baseline and the same with the
signature check; the same binary gives the same figures for both files). Then the pipeline's ratios to both
baselines, and SSIM by contact size (px: < 100, 100–300, 300–700, 700–1 500, ≥ 1 500), the bins of the model card.
"""
import json
import math
import statistics
import sys

METRICS = [
    ("SSIM", ("model", "depth", "ssim")),
    ("L1 [mm]", ("model", "depth", "l1_mm")),
    ("position, pipeline [mm]", ("model_combined", "pose", "position_mm")),
    ("theta, pipeline [rad]", ("model_combined", "pose", "theta_rad")),
    ("position, sample only [mm]", ("model", "pose", "position_mm")),
    ("position, threshold baseline [mm]", ("baseline", "pose", "position_mm")),
    ("position, baseline + check [mm]", ("baseline_checked", "pose", "position_mm")),
]
BINS = [(0, 100), (100, 300), (300, 700), (700, 1500), (1500, math.inf)]


def load(path):
    out = {}
    with open(path) as f:
        for n, line in enumerate(f, 1):
            try:
                row = json.loads(line)
            except json.JSONDecodeError as err:
                raise SystemExit(f"{path}: line {n} is not JSON ({err})")
            if "record" in row:
                out[(row["split"], row["index"])] = row["record"]
    if not out:
        raise SystemExit(f"{path}: no records (write them with `tnd eval ... --records FILE`)")
    return out


def get(record, keys):
    for k in keys:
        record = record.get(k) if isinstance(record, dict) else None
    return record if isinstance(record, (int, float)) and math.isfinite(record) else None


def paired(a, b, keys):
    xs, ys = [], []
    for k in a:
        x, y = get(a[k], keys), get(b[k], keys)
        if x is not None and y is not None:
            xs.append(x)
            ys.append(y)
    if not xs:
        return None
    d = [y - x for x, y in zip(xs, ys)]
    se = statistics.stdev(d) / math.sqrt(len(d)) if len(d) > 1 else float("nan")
    return {"n": len(d), "a": statistics.fmean(xs), "b": statistics.fmean(ys), "a_median": statistics.median(xs),
            "b_median": statistics.median(ys), "diff": statistics.fmean(d), "se": se}


def main():
    args = [a for a in sys.argv[1:] if a != "--json"]
    if len(args) != 2:
        raise SystemExit(__doc__.split("\n\n")[1])
    a, b = load(args[0]), load(args[1])
    if set(a) != set(b):
        raise SystemExit(f"{args[1]}: {len(set(a) ^ set(b))} pairs are in one file only; evaluate both models on the "
                         "same dataset, split, limit and seed")
    for k in a:
        if a[k].get("object") != b[k].get("object"):
            raise SystemExit(f"{args[1]}: pair {k[0]}/{k[1]} is object {b[k].get('object')!r}, "
                             f"{args[0]} has {a[k].get('object')!r}")
    res = {"pairs": len(a), "metrics": {}, "ssim_by_contact_px": []}
    for name, keys in METRICS:
        res["metrics"][name] = paired(a, b, keys)
    for model, src in (("a", a), ("b", b)):
        pipe = [get(r, ("model_combined", "pose", "position_mm")) for r in src.values()]
        base = [get(r, ("baseline", "pose", "position_mm")) for r in src.values()]
        chk = [get(r, ("baseline_checked", "pose", "position_mm")) for r in src.values()]
        ok = [(p, q, c) for p, q, c in zip(pipe, base, chk) if None not in (p, q, c)]
        if ok:
            p, q, c = (statistics.fmean(v) for v in zip(*ok))
            res[f"ratios_{model}"] = {"pipeline_over_baseline": p / q, "pipeline_over_checked_baseline": p / c}
    for lo, hi in BINS:
        sub = [k for k in a if lo <= a[k].get("contact_pixels", -1) < hi]
        m = paired({k: a[k] for k in sub}, {k: b[k] for k in sub}, ("model", "depth", "ssim"))
        res["ssim_by_contact_px"].append({"px": [lo, hi if hi < math.inf else None], **(m or {"n": 0})})
    if "--json" in sys.argv:
        print(json.dumps(res, indent=1))
        return
    print(f"{len(a)} pairs; A = {args[0]}, B = {args[1]}")
    print(f"{'metric':<36} {'A':>9} {'B':>9} {'B - A':>20}")
    for name, m in res["metrics"].items():
        if m is None:
            print(f"{name:<36} {'-':>9} {'-':>9}")
            continue
        med = f"  (medians {m['a_median']:.3g} / {m['b_median']:.3g})" if "position" in name else ""
        print(f"{name:<36} {m['a']:>9.4g} {m['b']:>9.4g} {m['diff']:>+11.4f} ± {m['se']:.4f}{med}")
    for model in ("a", "b"):
        r = res.get(f"ratios_{model}")
        if r:
            print(f"{model.upper()}: pipeline / baseline {r['pipeline_over_baseline']:.3f}, "
                  f"pipeline / (baseline + check) {r['pipeline_over_checked_baseline']:.3f}")
    base = [res["metrics"][n] for n in ("position, threshold baseline [mm]", "position, baseline + check [mm]")]
    if any(m is not None and (m["diff"] != 0 or m["se"] > 0) for m in base):
        print("note: the baselines differ between the files, so they were not made with the same binary and settings; "
              "the differences above mix the model with the rest of the pipeline")
    print("SSIM by contact size: " + "; ".join(
        f"{b['px'][0]}–{b['px'][1] or ''} px ({b['n']}): {b['a']:.3f} → {b['b']:.3f}" if b["n"] else
        f"{b['px'][0]}–{b['px'][1] or ''} px (0)" for b in res["ssim_by_contact_px"]))


if __name__ == "__main__":
    main()
