#!/usr/bin/env python3
"""Held-out calibration of the pose posterior: five folds by object over `tnd eval --records` files.

    python3 assets/validation/posterior_folds.py --tnd target/release/tnd --out DIR RECORDS.jsonl... [--folds 5]

Every pair goes to fold (index of its object among the sorted object names of all the records) mod --folds, so that
no object is in both a fit and its scoring. For each fold, `tnd posterior --fit` on the other folds' pairs (the
pipeline rows, `--method combined`), then `tnd posterior --config` on the fold's own; the held-out scores are pooled
over the folds: inside the 50 / 90 / 95 % regions, the mean negative log density of the truth, the confidently
wrong pairs, per contact-size bin. This is how sessions 28-30 compared posterior families (docs/uncertainty.md);
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
    ap.add_argument("records", nargs="+")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    files = [(p, *records(p)) for p in a.records]
    names = sorted({r["record"]["object"] for _, _, rs in files for r in rs})
    fold_of = {n: i % a.folds for i, n in enumerate(names)}
    pooled = {}
    for k in range(a.folds):
        parts = {"fit": [], "check": []}
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
        if not parts["fit"] or not parts["check"]:
            continue
        fit = os.path.join(a.out, f"fold{k}.json")
        if os.path.exists(fit):
            os.remove(fit)
        base = ["--config", a.base] if a.base else []
        fitted = subprocess.run([a.tnd, "posterior", "-q", "--method", "combined", "--json", "--force", "--fit",
                                 fit, *base, "--records", *parts["fit"]], capture_output=True, text=True)
        r = subprocess.run([a.tnd, "posterior", "-q", "--method", "combined", "--json", "--config", fit,
                            "--records", *parts["check"]], capture_output=True, text=True)
        if fitted.returncode != 0 or r.returncode != 0:
            sys.exit(f"fold {k}: tnd posterior failed: {(fitted.stderr + r.stderr).strip()[-1000:]}")
        for line in r.stdout.splitlines():
            row = json.loads(line)
            n = row["coverage"]["pairs"]
            if n == 0:
                continue
            p = pooled.setdefault(row["contact"], {"pairs": 0, "inside": [0.0, 0.0, 0.0], "wrong": 0, "nll": 0.0})
            p["pairs"] += n
            p["inside"] = [s + n * v for s, v in zip(p["inside"], row["coverage"]["inside"])]
            p["wrong"] += row["coverage"]["confidently_wrong"]
            m = row["reliability"]["pairs"]  # the mean NLL is over the pairs with a posterior
            p["nll_pairs"] = p.get("nll_pairs", 0) + m
            p["nll"] += m * row["reliability"]["mean_nll"]
    print("| contact | pairs | inside 50 / 90 / 95 % | mean NLL | confidently wrong |", file=sys.stderr)
    print("| --- | --- | --- | --- | --- |", file=sys.stderr)
    for contact, p in pooled.items():
        n = p["pairs"]
        row = {"contact": contact, "pairs": n, "inside": [v / n for v in p["inside"]],
               "mean_nll": p["nll"] / max(p.get("nll_pairs", 0), 1),
               "confidently_wrong": p["wrong"]}
        print(json.dumps(row))
        inside = " / ".join(f"{100 * v:.0f}" for v in row["inside"])
        print(f"| {contact} | {n} | {inside} | {row['mean_nll']:.2f} | {p['wrong']} |", file=sys.stderr)


if __name__ == "__main__":
    main()
