#!/usr/bin/env bash
# Retrain every committed result on the numeric pin (issue 27), resumably, from a git worktree at a
# fixed commit, so that editing the main checkout cannot break the workers mid-run:
#
#   git worktree add /work/retrain <commit> && cd /work/retrain
#   PY=/path/to/venv/bin/python STORE=/work/store-pinned bash scripts/retrain_pinned.sh
#
# Stages run in order and each is resumable (finished runs are never retrained). Before each
# stage, the partial exports under results/resume/ (committed at the end of a session) are
# imported into the stage's store, so a fresh machine picks up where the last one stopped.
# Before a session stops: `bash scripts/retrain_pinned.sh export EXPERIMENT...` writes the partial
# exports of the experiments named (of every one with a store when none is named).
# STAGES (default: all of "acrobot mcc doorkey mc-calibrate extended study") names the stages to run, so a session
# can skip those already committed on the pin, e.g. STAGES="mcc mc-calibrate study".
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-python3}
STORE=${STORE:-$PWD/results/_scratch/pinned}
WORKERS=${WORKERS:-2}
STAGES=${STAGES:-acrobot mcc doorkey mc-calibrate extended study}
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
mkdir -p "$STORE" results/resume
vlmrl() { "$PY" -m vlmrl_cli "$@"; }

# experiment name -> store file
declare -A DB=(
  [tasks-acrobot-calibrate]=acrobot.db [tasks-acrobot-study]=acrobot.db
  [tasks-mcc-calibrate]=mcc.db [tasks-mcc-study]=mcc.db
  [tasks-doorkey-calibrate]=doorkey.db [tasks-doorkey-study]=doorkey.db
  [vlmrl-calibrate]=calibration.db [vlmrl-study]=study.db
  [vlmrl-repro]=extended.db [sb3-default]=extended.db
)
uri() { echo "sqlite:///$STORE/${DB[$1]}"; }

on_pin() {  # true when every run in export $1 was trained on this package's numeric pin
  "$PY" - "$1" <<'PYEOF'
import sys
from pathlib import Path
from vlmrl_cli.core.numeric_pin import PIN_ID
from vlmrl_cli.tracking.transfer import read_records
runs = list(read_records(Path(sys.argv[1])))
sys.exit(0 if runs and all(r["tags"].get("vlmrl.pin") == PIN_ID for r in runs) else 1)
PYEOF
}

resume() {  # import experiment $1's partial export if one was committed, else its final export $2
  local file="results/resume/$1.jsonl.gz"    # when that is on the pin (a finished stage redraws)
  if [[ ! -f $file && -n ${2:-} && -f $2 ]] && on_pin "$2"; then file=$2; fi
  if [[ -f $file ]]; then vlmrl import "$file" --experiment "$1" --tracking-uri "$(uri "$1")"; fi
}

if [[ ${1:-} == export ]]; then  # the finished runs of unfinished stages, for the next session
  shift
  names=("$@")
  [[ ${#names[@]} -gt 0 ]] || names=("${!DB[@]}")
  for exp in "${names[@]}"; do
    [[ -f $STORE/${DB[$exp]} ]] || continue
    vlmrl export --experiment "$exp" --tracking-uri "$(uri "$exp")" --out "results/resume/$exp.jsonl.gz" || true
  done
  exit 0
fi

task_stage() {  # $1 short name, $2 task, $3 study regimes (space-separated; its calibration's closest first)
  local regimes=() r
  for r in $3; do regimes+=(--regime "$r"); done
  resume "tasks-$1-calibrate" "results/tasks/$2/runs-calibration.jsonl.gz"
  vlmrl calibrate --task "$2" --seeds 5 --workers "$WORKERS" --experiment "tasks-$1-calibrate" \
    --tracking-uri "$(uri "tasks-$1-calibrate")" --out "results/tasks/$2/calibration"
  vlmrl export --experiment "tasks-$1-calibrate" --tracking-uri "$(uri "tasks-$1-calibrate")" \
    --out "results/tasks/$2/runs-calibration.jsonl.gz"
  resume "tasks-$1-study" "results/tasks/$2/runs-study.jsonl.gz"
  vlmrl study --task "$2" "${regimes[@]}" --seeds 10 --alphas none --kin-scales none --query-flickers none \
    --workers "$WORKERS" --experiment "tasks-$1-study" --tracking-uri "$(uri "tasks-$1-study")" \
    --out "results/tasks/$2/study"
  vlmrl export --experiment "tasks-$1-study" --tracking-uri "$(uri "tasks-$1-study")" \
    --out "results/tasks/$2/runs-study.jsonl.gz"
}

want() { [[ " $STAGES " == *" $1 "* ]]; }

if want acrobot; then task_stage acrobot acrobot zoo-100k-lr1e-4; fi
if want mcc; then task_stage mcc mountain-car-continuous sb3-default-100k; fi
# DoorKey: zoo's knobs (the closest, where plain PPO fails) and SB3's defaults (where it learns)
if want doorkey; then task_stage doorkey minigrid-doorkey "zoo sb3-default-100k"; fi

# MountainCar's calibration: the default grid and the 2x2 grid (results/calibration/)
if want mc-calibrate; then
resume vlmrl-calibrate results/calibration/runs.jsonl.gz
vlmrl calibrate --workers "$WORKERS" --experiment vlmrl-calibrate --tracking-uri "$(uri vlmrl-calibrate)" \
  --out results/calibration
vlmrl calibrate --workers "$WORKERS" --grid ppo.normalize_reward=true,false --grid ppo.learning_rate=0.0003,0.0001 \
  --experiment vlmrl-calibrate --tracking-uri "$(uri vlmrl-calibrate)" --out results/calibration/grid-2x2
vlmrl export --experiment vlmrl-calibrate --tracking-uri "$(uri vlmrl-calibrate)" --out results/calibration/runs.jsonl.gz
fi

# results/extended/: the three ablations beside the repro's 20 runs (preset paper, 5 seeds), and
# untuned PPO (sb3-default, 3 seeds)
if want extended; then
resume vlmrl-repro results/report/runs.jsonl.gz
vlmrl run --arms vision-float,hybrid-no-rbf,hybrid-no-lock --seeds 5 --preset paper --workers "$WORKERS" \
  --experiment vlmrl-repro --tracking-uri "$(uri vlmrl-repro)"
vlmrl report --experiment vlmrl-repro --tracking-uri "$(uri vlmrl-repro)" --out results/extended/all-arms
vlmrl export --experiment vlmrl-repro --tracking-uri "$(uri vlmrl-repro)" --out results/extended/all-arms/runs.jsonl.gz
resume sb3-default results/extended/sb3-default/runs.jsonl.gz
vlmrl run --arms baseline,hybrid --seeds 3 --preset sb3-default --workers "$WORKERS" \
  --experiment sb3-default --tracking-uri "$(uri sb3-default)"
vlmrl report --experiment sb3-default --tracking-uri "$(uri sb3-default)" --out results/extended/sb3-default
vlmrl export --experiment sb3-default --tracking-uri "$(uri sb3-default)" --out results/extended/sb3-default/runs.jsonl.gz
fi

# the study (its default grid, 20 seeds), then the learning-rate refinement on the same store
if want study; then
resume vlmrl-study
vlmrl study --out results/study --experiment vlmrl-study --tracking-uri "$(uri vlmrl-study)" --workers "$WORKERS"
vlmrl calibrate --seeds 20 --set ppo.normalize_reward=false --grid ppo.learning_rate=0.00015,0.0002 \
  --experiment vlmrl-study --tracking-uri "$(uri vlmrl-study)" --out results/calibration/refine-lr --workers "$WORKERS"
vlmrl export --experiment vlmrl-study --tracking-uri "$(uri vlmrl-study)" --out results/study/runs/pinned.jsonl.gz
fi
