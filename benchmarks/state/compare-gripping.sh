#!/bin/bash
source ~/venv/bin/activate
cd /work/main
export DBTOOL_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 TI_LOG_LEVEL=warn
d=~/.cache/dbtool/compare35m
if [ -d $d ]; then r=--resume; else r=--no-resume; fi
nice -n 19 dbtool compare --budget quick --tasks gripping --methods all --seeds 0 1 2 3 4 5 6 7 --executor serial --threads 1 --out $d $r
