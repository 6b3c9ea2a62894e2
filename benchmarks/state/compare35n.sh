#!/bin/bash
# the quick comparison on gripping, 8 seeds, after the design runs; resumable
source ~/venv/bin/activate
cd /work/main
export DBTOOL_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 TI_LOG_LEVEL=warn
while pgrep -f "q.sh" > /dev/null; do sleep 30; done
METHODS=${METHODS:-all}
d=~/.cache/dbtool/compare35n
if [ -f $d/compare.json ]; then r=--resume; else r=--no-resume; fi
dbtool compare --budget quick --tasks gripping --methods $METHODS --seeds 0 1 2 3 4 5 6 7 --executor local --workers ${WORKERS:-2} --threads 1 --out $d $r
