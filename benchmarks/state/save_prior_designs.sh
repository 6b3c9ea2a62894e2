#!/bin/bash
# Copy the prior-designs runs (benchmarks/state/prior-designs.sh) into the work tree: the small
# files of finished runs, every file of an unfinished one (it resumes from them).
set -e
SRC=~/.cache/dbtool/item5/runs
DST=$(dirname "$0")/prior-designs
mkdir -p "$DST"
for d in "$SRC"/*; do
  n=$(basename "$d")
  mkdir -p "$DST/$n"
  if [ -f "$d/design.npz" ]; then
    rm -f "$DST/$n"/checkpoint.pt "$DST/$n"/trajectory.npz "$DST/$n"/best.npz
    cp "$d"/{config.json,manifest.json,metrics.jsonl,design.npz,montage.png,performance.png} "$DST/$n/"
  else
    cp "$d"/* "$DST/$n/" 2>/dev/null || true
  fi
done
du -sh "$DST"
