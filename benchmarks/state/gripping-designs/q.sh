#!/bin/bash
# usage: q.sh SEED... ; one design run after another, 1 thread, resumable
source ~/venv/bin/activate
cd /work/main
export DBTOOL_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 TI_LOG_LEVEL=warn
for s in "$@"; do
  d=~/.cache/dbtool/grip35c/seed$s
  if [ -f $d/design.npz ]; then continue; fi
  start=$(date +%s)
  if [ -d $d ]; then dbtool design gripping --seed $s --resume $d >> $d.log 2>&1; else dbtool design gripping --seed $s --run-dir $d > $d.log 2>&1; fi
  echo "seed $s rc=$? $(( $(date +%s) - start )) s" >> ~/.cache/dbtool/grip35c/times.txt
done
