#!/bin/bash
# copy a comparison's finished cells (record, progress rows, design) into the repository
# usage: save_compare.sh SRC DST
src=$1; dst=$2
mkdir -p "$dst/cells"
# the folder's own files only the first time: several runs (one per method and commit) fill
# the same table, and benchmarks/compare_report.py redraws its report from the cells
for f in compare.json manifest.json results.csv; do
  [ -f "$dst/$f" ] || cp "$src/$f" "$dst/" 2>/dev/null
done
for c in "$src"/cells/*; do
  if grep -q '"status": "done"' "$c/cell.json" 2>/dev/null; then
    mkdir -p "$dst/cells/$(basename $c)"
    cp "$c"/cell.json "$c"/metrics.jsonl "$c"/design.npz "$dst/cells/$(basename $c)/"
  fi
done
