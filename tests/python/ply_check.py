#!/usr/bin/env python3
"""CI check: trimesh reads the PLY files `tnd pose` writes (binary or ASCII) and finds what pose.json says is in
them: the point counts, and for the object meshes a closed (watertight) surface with the object's volume at every
estimated pose (a rigid motion keeps it).

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
assert volumes and max(volumes) - min(volumes) < 1e-9 * max(1.0, max(volumes)) + 1e-12, volumes
print(f"trimesh read {len(summary['geometry'])} PLY files; object volume {volumes[0] * 1e6:.3f} cm^3")
