#!/usr/bin/env bash
# Issue 41's long runs, resumably, from a git worktree at a fixed commit (so that editing the main
# checkout cannot break the workers mid-run):
#
#   git worktree add /work/wt41 <commit> && cd /work/wt41
#   PY=/path/to/venv/bin/python STORE=/work/store41 WORKERS=1 bash scripts/issue41_runs.sh
#
# Stages (STAGES, default "doorkey acrobot mcc"): each task's study at its own scales (Task.scales)
# with the six arms, the potential-form dense arm among them, and its 3 x 3 dose-response (alpha in
# {0, A, 2A} x kin_scale in {0, K, 2K}, A and K the task's scales, plus the placebo at 2A).
# Before each stage the partial export under results/resume/ (committed at the end of a session) is
# imported, so a fresh machine picks up where the last one stopped; Acrobot's and
# MountainCarContinuous's committed studies are imported too, so their baselines (the same config
# hash) are not retrained. `bash scripts/issue41_runs.sh export` writes the partial exports.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-python3}
STORE=${STORE:-$PWD/results/_scratch/issue41}
WORKERS=${WORKERS:-1}
STAGES=${STAGES:-doorkey acrobot mcc}
export PYTHONPATH=$PWD OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
mkdir -p "$STORE" results/resume
vlmrl() { "$PY" -m vlmrl_cli "$@"; }
ARMS=baseline,hybrid,hybrid-shuffled,kinematic,semantic,hybrid-dense-pbrs
declare -A EXP=([doorkey]=tasks-doorkey-study [acrobot]=tasks-acrobot-scaled [mcc]=tasks-mcc-scaled)
uri() { echo "sqlite:///$STORE/$1.db"; }

if [[ ${1:-} == export ]]; then
  for s in "${!EXP[@]}"; do
    [[ -f $STORE/$s.db ]] || continue
    vlmrl export --experiment "${EXP[$s]}" --tracking-uri "$(uri "$s")" --out "results/resume/${EXP[$s]}.jsonl.gz" || true
  done
  exit 0
fi

stage() {  # $1 short, $2 task, $3 regime, $4 alphas, $5 kin-scales, $6 committed export to import first (or "")
  local exp=${EXP[$1]} u
  u=$(uri "$1")
  if [[ ! -f $STORE/$1.db ]]; then
    # a finished stage's own export, else the partial one a session left under results/resume/
    local done_file=results/tasks/$2/runs-study-scaled.jsonl.gz
    if [[ -f $done_file ]]; then vlmrl import "$done_file" --experiment "$exp" --tracking-uri "$u"
    elif [[ -f results/resume/$exp.jsonl.gz ]]; then vlmrl import "results/resume/$exp.jsonl.gz" --experiment "$exp" --tracking-uri "$u"
    fi
    [[ -n $6 ]] && vlmrl import "$6" --experiment "$exp" --tracking-uri "$u"
  fi
  vlmrl study --task "$2" --regime "$3" --seeds 10 --arms $ARMS --alphas "$4" --kin-scales "$5" \
    --query-flickers none --profiles none --flickers none --workers "$WORKERS" --experiment "$exp" \
    --tracking-uri "$u" --out "results/tasks/$2/study-scaled"
  vlmrl export --experiment "$exp" --tracking-uri "$u" --out "results/tasks/$2/runs-study-scaled.jsonl.gz"
}

want() { [[ " $STAGES " == *" $1 "* ]]; }
# alpha and kin_scale: each task's Task.scales (docs/method.md, "The two scales, per task") and twice it
if want doorkey; then stage doorkey minigrid-doorkey zoo 0.241,0.482 0,0.172,0.344 ""; fi
if want acrobot; then stage acrobot acrobot zoo-100k-lr1e-4 107,214 0,0.152,0.304 results/tasks/acrobot/runs-study.jsonl.gz; fi
if want mcc; then
  stage mcc mountain-car-continuous sb3-default-100k 22.1,44.2 0,0.0221,0.0442 \
    results/tasks/mountain-car-continuous/runs-study.jsonl.gz
fi
