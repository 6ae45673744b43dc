#!/bin/bash
# `tnd pose --press auto` against a fixed press and the true one, on `tnd sim` imprints of three objects at two poses
# and three presses (4 samples, seed 3). Prints one line per run: object pose true-press variant press_m position_err_mm
# baseline_mm. MESHES holds two public meshes this project did not make:
#   cura_UltimakerRobot_support.stl  Debian package cura 4.13, /usr/share/cura/resources/meshes (mm)
#   allegro_link_3.0_tip.STL         PyPI package example-robot-data 6.0.0 (m)
# Usage: MESHES=dir TND=target/release/tnd bash assets/validation/press_auto.sh OUT_DIR > results.txt
set -euo pipefail
OUT=${1:?output directory}
TND=${TND:-tnd}
mkdir -p "$OUT"
for obj in "cross_w12_s50|" "$MESHES/cura_UltimakerRobot_support.stl|--units mm" "$MESHES/allegro_link_3.0_tip.STL|--units m"; do
  o=${obj%%|*}; u=${obj##*|}
  for pose in "0.002,-0.001,0.35" "-0.004,0.003,1.3"; do
    for press in 0.0025 0.0045 0.007; do
      d="$OUT/$(basename "$o")_${pose}_$press"
      # shellcheck disable=SC2086
      "$TND" sim --object "$o" $u --pose="$pose" --press "$press" --seed 3 --out "$d" >/dev/null 2>&1 || continue
      for variant in auto 0.006 "$press"; do
        # shellcheck disable=SC2086
        r=$("$TND" pose --imprint "$d/imprint.npy" --signature "$d/signature.npy" --object "$o" $u --truth="$pose" \
              --samples 4 --press "$variant" --out "$d/pose_$variant" 2>/dev/null | tail -1) || continue
        echo "$(basename "$o") $pose $press $variant $(echo "$r" | python3 -c 'import json, sys
d = json.load(sys.stdin)
print(d["press_m"], d["estimate_error"]["position_mm"], d["baseline"]["position_mm"] if d["baseline"] else "")')"
      done
    done
  done
done
