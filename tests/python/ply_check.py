#!/usr/bin/env python3
"""CI check: trimesh reads the PLY files `tnd pose` writes (binary or ASCII) and finds what pose.json says is in
them: the point counts, and for the object meshes a closed (watertight) surface with the object's volume at every
estimated pose (a rigid motion keeps it); the pose posterior written into object_estimate.ply's header comments
equals pose.json's (each mode's core and tail moment-matched), and posterior_region_points.ply holds 64 points per mode on the table (z = 0).

    python tests/python/ply_check.py OUT/pose.json
"""
import json
import math
import sys

import trimesh

with open(sys.argv[1]) as f:
    summary = json.load(f)
volumes = []
for entry in summary["geometry"]:
    path, count = entry["path"], entry["vertices"]
    loaded = trimesh.load(path, process=False)
    assert len(loaded.vertices) == count, (path, len(loaded.vertices), count)
    assert all(math.isfinite(v) for v in loaded.vertices.flatten()), path
    if path.endswith("_points.ply"):
        assert isinstance(loaded, trimesh.PointCloud), (path, type(loaded))
    else:
        assert isinstance(loaded, trimesh.Trimesh), (path, type(loaded))
        assert loaded.is_watertight, path
        volumes.append(loaded.volume)

def header_comments(path):
    with open(path, "rb") as f:
        head = f.read(1 << 16).split(b"end_header")[0].decode()
    return [l[len("comment "):] for l in head.splitlines() if l.startswith("comment ")]


posterior = summary.get("posterior")
if posterior:
    by_name = {e["path"].rsplit("/", 1)[-1]: e for e in summary["geometry"]}
    modes = [c.split() for c in header_comments(by_name["object_estimate.ply"]["path"])
             if c.startswith("posterior mode ")]
    assert len(modes) == len(posterior["modes"]), (len(modes), len(posterior["modes"]))
    for words, mode in zip(modes, posterior["modes"]):
        weight = float(words[words.index("weight") + 1])
        mean = [float(w) for w in words[words.index("mean") + 1:words.index("mean") + 4]]
        cov = [float(w) for w in words[words.index("cov") + 1:]]
        assert math.isclose(weight, mode["weight"], rel_tol=1e-12), (weight, mode["weight"])
        assert all(math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-15) for a, b in zip(mean, mode["mean"]))
        # The comment carries the spread to act on: the core and its tail moment-matched (PosteriorMode::spread_cov),
        # the far component left out (its share is in pose.json).
        tails = mode.get("tails") or {"tail": 0.0, "far": 0.0}
        near = 1.0 - tails["far"]
        if tails["tail"] > 0.0 and near > 0.0:
            core, tail = (near - tails["tail"]) / near, tails["tail"] / near
            flat = [core * c + tail * t for row, trow in zip(mode["cov"], tails["tail_cov"]) for c, t in zip(row, trow)]
        else:
            flat = [c for row in mode["cov"] for c in row]
        assert len(cov) == 9 and all(math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-30) for a, b in zip(cov, flat))
    rings = trimesh.load(by_name["posterior_region_points.ply"]["path"], process=False)
    assert len(rings.vertices) == 64 * len(posterior["modes"]), len(rings.vertices)
    assert abs(rings.vertices[:, 2]).max() == 0.0
    print(f"the posterior's {len(modes)} modes read back from the PLY header")
assert volumes and max(volumes) - min(volumes) < 1e-9 * max(1.0, max(volumes)) + 1e-12, volumes
print(f"trimesh read {len(summary['geometry'])} PLY files; object volume {volumes[0] * 1e6:.3f} cm^3")
