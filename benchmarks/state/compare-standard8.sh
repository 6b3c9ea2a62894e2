#!/bin/bash
# The 8-seed standard table (issue 66 item 4): prior samples and DiffuseBot on the six tasks,
# seeds 0-7, 100 units a cell, resumable: finished cells are skipped. Runs from a git worktree
# pinned at one commit (benchmarks/state/README.md):
#   git worktree add --detach ~/.cache/dbtool/standard8/tree COMMIT
# METHODS (default prior), TASKS (default all) and SEEDS (default 3 4 5 6 7) pick the cells;
# the seeds run one after another, so the table fills seed by seed. WORKERS (default 1).
source ${VENV:-/work/venv}/bin/activate
T=${TREE:-~/.cache/dbtool/standard8/tree}
d=${OUT:-~/.cache/dbtool/standard8/out}
cd $T || exit 1
export PYTHONPATH=$T DBTOOL_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 TI_LOG_LEVEL=warn
for s in ${SEEDS:-3 4 5 6 7}; do
  if [ -f $d/compare.json ]; then r=--resume; else r=--no-resume; fi
  nice -n 5 python -c "import sys; from dbtool.cli import main; sys.argv[0] = 'dbtool'; main()" \
    compare --budget standard $(for t in ${TASKS:-all}; do echo --tasks $t; done) \
    $(for m in ${METHODS:-prior}; do echo --methods $m; done) --seeds $s --executor local \
    --workers ${WORKERS:-1} --threads 1 --out $d $r || exit 1
done
