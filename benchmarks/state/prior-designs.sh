#!/bin/bash
# Issue 39 item 5: design runs (quick) on priors 1 and 3, seeds 0-3, then the embedding
# experiments on prior 3. Resumable: finished runs are skipped, unfinished ones resumed.
# PRIORS (default "1 3") picks the prior versions; EMBEDDING=0 skips the embedding part.
source ~/venv/bin/activate
T=~/.cache/dbtool/item5/tree  # git worktree at 7156fd5 (version 3 with its guidance interval)
R=~/.cache/dbtool/item5/runs
mkdir -p $R
cd $T
export PYTHONPATH=$T
for seed in 0 1 2 3; do
  for task in crawling gripping; do
    for p in ${PRIORS:-1 3}; do
      d=$R/$task-p$p-s$seed
      if [ -f $d/design.npz ]; then continue; fi
      echo "$(date +%T) design $task prior $p seed $seed"
      if [ -f $d/checkpoint.pt ]; then
        python -c "import sys; from dbtool.cli import main; sys.argv[0]='dbtool'; main()" design $task --resume $d --no-report || exit 1
      else
        rm -rf $d
        python -c "import sys; from dbtool.cli import main; sys.argv[0]='dbtool'; main()" design $task --preset quick --seed $seed --prior $p --run-dir $d --no-report || exit 1
      fi
    done
  done
done
[ "${EMBEDDING:-1}" = 0 ] && exit 0
for space in free mixture; do
  echo "$(date +%T) embedding $space prior 3"
  python benchmarks/codesign.py embedding --space $space --prior 3 --seeds 0 1 2 3 --tasks crawling gripping || exit 1
done
echo "$(date +%T) all done"
