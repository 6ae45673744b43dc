#!/usr/bin/env bash
# Simulate the press recordings of assets/validation/track_presses.txt and track each one (tnd recording track at its
# defaults, scored against the recording's pose topic), for the track calibration of
# docs/experiments/2026-11-30-track-calibration.md:
#
#   assets/validation/track_presses.sh TND MESHES OUT [--per-frame]
#
# TND: the tnd binary; MESHES: the real validation meshes (assets/validation/fetch_real_meshes.py); OUT: recordings
# go to OUT/rec, tracks to OUT/trk_carried (or OUT/trk_perframe with --per-frame). Finished tracks are skipped, so a
# killed run goes on where it stopped. Then: tnd posterior --tracks OUT/trk_carried/*/ (as recorded), and
# assets/validation/posterior_folds.py --tracks ... (a calibration fitted to tracks, held out by object).
set -u
tnd=$1; meshes=$2; out=$3; mode=${4:-}
kind=carried; [ "$mode" = --per-frame ] && kind=perframe
list="$(dirname "$0")/track_presses.txt"
mkdir -p "$out/rec" "$out/trk_$kind"
grep -v '^#' "$list" | while read -r name pose press tof seed; do
  rec="$out/rec/$name.mcap"
  if [ ! -f "$rec" ]; then
    extra=(); [ "$tof" = 1 ] && extra=(--tof)
    "$tnd" recording simulate -q --objects "$meshes" --object "$name" --pose="$pose" --max-press "$press" \
      --seed "$seed" "${extra[@]}" "$rec" > /dev/null || { echo "simulate failed: $name"; continue; }
  fi
  trk="$out/trk_$kind/$name"
  grep -qs summary "$trk/track.json" && continue
  "$tnd" recording track "$rec" --objects "$meshes" --object "$name" --out "$trk" -q $mode > "$trk.out" 2> "$trk.err" \
    || echo "track failed: $name ($(tail -1 "$trk.err"))"
done
