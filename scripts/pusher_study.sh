#!/usr/bin/env bash
# Pusher-v5's study (issue 54), resumable: it trains, with the code of the worktree ROOT, what its
# store lacks: a wave of 3 seeds per arm, then 10, one job per worker. Rerunning it resumes. The study
# started at d0221fd; on 2026-12-08 its workers moved to 5cbcbc2, then 59ce292, whose RBF gives the
# same bits faster (`vlmrl verify` retrained the d0221fd runs hybrid-s1 at 63e7eda and hybrid-s2 at
# 59ce292: identical, 5016 episodes each). A new session imports the committed partial export first:
#
#   git worktree add ../bg-pstudy3 59ce292 && cd ../bg-pstudy3
#   ROOT=$PWD IMPORTS=/path/to/main/results/tasks/pusher/runs-study-partial.jsonl.gz V=/path/to/venv/bin/vlmrl \
#       nohup bash /path/to/main/scripts/pusher_study.sh > study.log 2>&1 &
#
# Before a session ends: vlmrl export --experiment tasks-pusher-study --tracking-uri "sqlite:///$PWD/results/_scratch/pusher-study.db" \
#     --out .../results/tasks/pusher/runs-study-partial.jsonl.gz
# and, since its hybrid runs change Pusher's measured VLM hit rate, update ``VLM_HIT_RATES`` in
# vlmrl_cli/sweep/cost.py to what ``measure_hit_rates(committed_exports())`` prints
# (tests/sweep/test_cost.py checks that the table is what the committed exports measure).
set -u
cd "${ROOT:-$(dirname "$0")/..}"
mkdir -p results/_scratch
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
V=${V:-vlmrl}
URI=sqlite:///$PWD/results/_scratch/pusher-study.db
EXP=tasks-pusher-study
ARGS=(--task pusher --regime pusher --arms baseline,kinematic,hybrid,semantic,hybrid-shuffled,hybrid-dense-pbrs
      --alphas none --kin-scales none --query-flickers none --profiles none --flickers none
      --experiment $EXP --tracking-uri "$URI")
date
for f in ${IMPORTS:-}; do "$V" import "$f" --experiment $EXP --tracking-uri "$URI" || true; done
for n in 3 10; do "$V" study "${ARGS[@]}" --seeds $n --workers "${WORKERS:-1}" --out results/_scratch/study-$n; done
date
