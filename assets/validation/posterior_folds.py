#!/usr/bin/env python3
"""Held-out calibration of the pose posterior: five folds by object over `tnd eval --records` files and
`tnd recording track` folders.

    python3 assets/validation/posterior_folds.py --tnd target/release/tnd --out DIR [RECORDS.jsonl...] \
        [--tracks TRACK_DIR...] [--folds 5]

Every pair (and every track, by its object) goes to fold (index of its object among the sorted object names of all
the inputs) mod --folds, so that no object is in both a fit and its scoring. For each fold, `tnd posterior --fit` on
the other folds' pairs (the pipeline rows, `--method combined`, and the tracks' frames), then `tnd posterior
--config` on the fold's own; the held-out scores are pooled over the folds per row kind (combined, track): inside the
50 / 90 / 95 % regions, the mean negative log density of the truth, the confidently wrong pairs, per contact-size
bin, and the folds' range of median θ half-width (±68 %) and σθ against the median θ error. This is how sessions 28-30 compared posterior families (docs/uncertainty.md);
nothing in it looks at a test set. Prints one JSON line per bin and a Markdown table. Needs only Python's standard
library.
"""

import argparse
import json
import os
import subprocess
import sys


def records(path):
    """The settings line and the record lines of one records file."""
    with open(path) as f:
        lines = [json.loads(line) for line in f if line.strip()]
    return [l for l in lines if "settings" in l], [l for l in lines if "record" in l]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tnd", default="tnd")
    ap.add_argument("--out", required=True, help="folder for the folds' records and fits")
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--base", help="calibration the fits start from and keep the unfitted settings of (e.g. "
                    "rival_window_nats); the shipped default without it")
    ap.add_argument("--tracks", nargs="+", default=[], help="folders of tnd recording track (scored)")
    ap.add_argument("records", nargs="*")
    a = ap.parse_args()
    if not a.records and not a.tracks:
        sys.exit("give records files, --tracks folders or both")
    os.makedirs(a.out, exist_ok=True)
    files = [(p, *records(p)) for p in a.records]
    track_object = {}
    for d in a.tracks:
        with open(os.path.join(d, "track.json")) as f:
            track_object[d] = json.load(f)["summary"]["object"]
    names = sorted({r["record"]["object"] for _, _, rs in files for r in rs} | set(track_object.values()))
    fold_of = {n: i % a.folds for i, n in enumerate(names)}
    pooled = {}
    sharpness = {}
    for k in range(a.folds):
        parts = {"fit": [], "check": []}
        tracks = {"fit": [d for d, n in track_object.items() if fold_of[n] != k],
                  "check": [d for d, n in track_object.items() if fold_of[n] == k]}
        for n, (path, head, rs) in enumerate(files):
            for part, keep in (("fit", lambda r: fold_of[r["record"]["object"]] != k),
                               ("check", lambda r: fold_of[r["record"]["object"]] == k)):
                mine = [r for r in rs if keep(r)]
                if mine:
                    out = os.path.join(a.out, f"fold{k}-{part}-{n}.jsonl")
                    with open(out, "w") as f:
                        for line in head + mine:
                            f.write(json.dumps(line) + "\n")
                    parts[part].append(out)
        if not (parts["fit"] or tracks["fit"]) or not (parts["check"] or tracks["check"]):
            continue
        fit = os.path.join(a.out, f"fold{k}.json")
        if os.path.exists(fit):
            os.remove(fit)
        base = ["--config", a.base] if a.base else []
        def inputs(part):
            return ((["--records", *parts[part]] if parts[part] else [])
                    + (["--tracks", *tracks[part]] if tracks[part] else []))
        fitted = subprocess.run([a.tnd, "posterior", "-q", "--method", "combined", "--json", "--force", "--fit",
                                 fit, *base, *inputs("fit")], capture_output=True, text=True)
        r = subprocess.run([a.tnd, "posterior", "-q", "--method", "combined", "--json", "--config", fit,
                            *inputs("check")], capture_output=True, text=True)
        if fitted.returncode != 0 or r.returncode != 0:
            sys.exit(f"fold {k}: tnd posterior failed: {(fitted.stderr + r.stderr).strip()[-1000:]}")
        for line in r.stdout.splitlines():
            row = json.loads(line)
            n = row["coverage"]["pairs"]
            if n == 0:
                continue
            key = (row["rows"], row["contact"])
            if row["contact"] == "all":
                rel = row["reliability"]
                sharpness.setdefault(row["rows"], []).append(
                    (rel.get("median_half_width_theta_deg"), rel.get("median_sigma_theta_deg"),
                     rel.get("median_error_theta_deg")))
            p = pooled.setdefault(key, {"pairs": 0, "inside": [0.0, 0.0, 0.0], "wrong": 0, "nll": 0.0})
            p["pairs"] += n
            p["inside"] = [s + n * v for s, v in zip(p["inside"], row["coverage"]["inside"])]
            p["wrong"] += row["coverage"]["confidently_wrong"]
            m = row["reliability"]["pairs"]  # the mean NLL is over the pairs with a posterior
            p["nll_pairs"] = p.get("nll_pairs", 0) + m
            p["nll"] += m * row["reliability"]["mean_nll"]
    print("| rows | contact | pairs | inside 50 / 90 / 95 % | mean NLL | confidently wrong |", file=sys.stderr)
    print("| --- | --- | --- | --- | --- | --- |", file=sys.stderr)
    for (rows, contact), p in pooled.items():
        n = p["pairs"]
        row = {"rows": rows, "contact": contact, "pairs": n, "inside": [v / n for v in p["inside"]],
               "mean_nll": p["nll"] / max(p.get("nll_pairs", 0), 1),
               "confidently_wrong": p["wrong"]}
        print(json.dumps(row))
        inside = " / ".join(f"{100 * v:.0f}" for v in row["inside"])
        print(f"| {rows} | {contact} | {n} | {inside} | {row['mean_nll']:.2f} | {p['wrong']} |", file=sys.stderr)
    for rows, folds in sharpness.items():
        print(json.dumps({"rows": rows, "folds_theta_deg": [
            {"half_width_68": h, "sigma": s, "error": e} for h, s, e in folds]}))
        ratios = [h / e for h, _, e in folds if h and e]
        if ratios:
            print(f"{rows}: median ±68 % θ / median θ error per fold {min(ratios):.1f}-{max(ratios):.1f}x",
                  file=sys.stderr)


if __name__ == "__main__":
    main()
