#!/usr/bin/env python3
"""numpy round trip of the dataset format (run by .ci/run after `cargo test --workspace`).

The Rust test `write_numpy_round_trip_fixture` (tests/dataset.rs) generates a small dataset and writes
expected.json next to it: for two pairs, the noise-free target and mask re-simulated from the stored metadata,
and that metadata. This script opens the shards with numpy only (no tactile-derender code) and checks:
  * every shard's size and sha256 against manifest.json, and the per-split counts;
  * the fixed array names, dtypes (float32 images (N, H, W) in metres, float64 poses, uint64 seeds, int32 indices);
  * target and mask of the two pairs equal the re-simulated values exactly, and their metadata matches;
  * Y = R - S wherever both are seen, mask == (target > 0), contact_pixels == mask.sum().

usage: dataset_numpy_check.py DIR   (DIR = <target>/tmp/tnd-dataset-numpy)
"""
import hashlib
import json
import os
import sys

import numpy as np

IMAGES = {"imprint", "target", "signature", "reference", "mask"}
META = {"index": "<u8", "seed": "<u8", "object": "<i4", "pose": "<f8", "press": "<f8", "sensor": "<f8",
        "contact_pixels": "<i4"}


def fail(msg):
    print(f"dataset_numpy_check: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def main(root):
    expected = json.load(open(os.path.join(root, "expected.json")))
    ds = expected["dataset"]
    manifest = json.load(open(os.path.join(ds, "manifest.json")))
    if manifest["version"] != 1:
        fail(f"manifest version {manifest['version']}")
    width, height = manifest["resolution"]
    objects = [o["name"] for o in manifest["object_set"]["manifest"]["objects"]]
    counts = {"train": 0, "unseen_poses": 0, "unseen_objects": 0}
    rows = {s: [] for s in counts}  # split -> list of (shard arrays, row)
    for entry in manifest["shards"]:
        path = os.path.join(ds, entry["file"])
        data = open(path, "rb").read()
        if len(data) != entry["bytes"]:
            fail(f"{path}: {len(data)} bytes, manifest says {entry['bytes']}")
        if hashlib.sha256(data).hexdigest() != entry["sha256"]:
            fail(f"{path}: sha256 mismatch")
        z = np.load(path)
        if set(z.files) != IMAGES | set(META):
            fail(f"{path}: arrays {sorted(z.files)}")
        n = entry["pairs"]
        arrays = {k: z[k] for k in z.files}
        for k in IMAGES:
            a = arrays[k]
            if a.dtype != np.dtype("<f4") or a.shape != (n, height, width):
                fail(f"{path}: {k} is {a.dtype} {a.shape}, expected float32 {(n, height, width)}")
            if not np.isfinite(a).all():
                fail(f"{path}: {k} has non-finite values")
        for k, dt in META.items():
            if arrays[k].dtype != np.dtype(dt) or arrays[k].shape[0] != n:
                fail(f"{path}: {k} is {arrays[k].dtype} {arrays[k].shape}")
        if not (arrays["mask"] == (arrays["target"] > 0)).all():
            fail(f"{path}: mask != (target > 0)")
        if not (arrays["contact_pixels"] == arrays["mask"].sum(axis=(1, 2))).all():
            fail(f"{path}: contact_pixels != mask sum")
        r, s = arrays["reference"], arrays["signature"]
        y = np.where((r > 0) & (s > 0), r - s, np.float32(0))
        if not (arrays["imprint"] == y).all():
            fail(f"{path}: imprint != R - S")
        counts[entry["split"]] += n
        rows[entry["split"]].extend((arrays, i) for i in range(n))
    for split, c in counts.items():
        if manifest["counts"][split] != c:
            fail(f"counts[{split}] = {manifest['counts'][split]}, shards hold {c}")
    for p in expected["pairs"]:
        arrays, i = rows[p["split"]][p["split_index"]]
        tgt = np.array(p["target"], dtype=np.float32).reshape(height, width)
        msk = np.array(p["mask"], dtype=np.float32).reshape(height, width)
        if not np.array_equal(arrays["target"][i], tgt):
            fail(f"pair {p['index']}: target differs from the re-simulation "
                 f"(max |diff| {np.abs(arrays['target'][i] - tgt).max()} m)")
        if not np.array_equal(arrays["mask"][i], msk):
            fail(f"pair {p['index']}: mask differs")
        if int(arrays["index"][i]) != p["index"] or str(int(arrays["seed"][i])) != p["seed"]:
            fail(f"pair {p['index']}: index/seed differ")
        if objects[int(arrays["object"][i])] != p["object"]:
            fail(f"pair {p['index']}: object differs")
        if arrays["pose"][i].tolist() != p["pose"] or float(arrays["press"][i]) != p["press"]:
            fail(f"pair {p['index']}: pose/press differ")
    print(f"dataset_numpy_check: OK ({sum(counts.values())} pairs, {len(manifest['shards'])} shards, numpy {np.__version__})")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    main(sys.argv[1])
