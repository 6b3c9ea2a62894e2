#!/bin/bash
# copy a comparison's finished cells (record, progress rows, design) into the repository
# usage: save_compare.sh SRC DST
src=$1; dst=$2
mkdir -p "$dst/cells"
cp "$src"/compare.json "$src"/manifest.json "$dst"/ 2>/dev/null
cp "$src"/results.csv "$dst"/ 2>/dev/null
for c in "$src"/cells/*; do
  if grep -q '"status": "done"' "$c/cell.json" 2>/dev/null; then
    mkdir -p "$dst/cells/$(basename $c)"
    cp "$c"/cell.json "$c"/metrics.jsonl "$c"/design.npz "$dst/cells/$(basename $c)/"
  fi
done
