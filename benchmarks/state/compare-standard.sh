#!/bin/bash
# The standard comparison (108 cells: six methods x six tasks x seeds 0-2, 100 units each),
# resumable: finished cells are skipped. Runs from a git worktree pinned at one commit, so that
# every cell of the table runs the same code across sessions:
#   git worktree add --detach ~/.cache/dbtool/standard/tree COMMIT   (benchmarks/state/README.md)
# WORKERS (default 2) local worker processes, one thread each; TASKS and METHODS (default all)
# run a part of the table into the same folder (a resume adds the requested cells).
source ~/venv/bin/activate
T=~/.cache/dbtool/standard/tree
d=~/.cache/dbtool/standard/out
cd $T || exit 1
export PYTHONPATH=$T DBTOOL_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 TI_LOG_LEVEL=warn
if [ -f $d/compare.json ]; then r=--resume; else r=--no-resume; fi
exec python -c "import sys; from dbtool.cli import main; sys.argv[0] = 'dbtool'; main()" \
  compare --budget standard $(for t in ${TASKS:-all}; do echo --tasks $t; done) \
  $(for m in ${METHODS:-all}; do echo --methods $m; done) --seeds ${SEEDS:-0 1 2} --executor local \
  --workers ${WORKERS:-2} --threads 1 --out $d $r
