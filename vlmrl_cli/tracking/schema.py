"""The tracking contract: every MLflow tag key, tag value and metric key vlmrl writes or reads,
spelled only through these names; ``search_all`` is the one paginated ``search_runs``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from vlmrl_cli.core.errors import BadInput

TAG_PREFIX = "vlmrl."
#: The per-episode table a training run writes at its end: ``timestep``, then ``EPISODE_METRICS``.
EPISODES_TABLE = "episodes.csv"
#: A training run's artifacts: its config, SB3's model (a zip whose ``policy.pth`` entry holds the
#: policy's weights; the rest of it is cloudpickle), those weights alone as an export carries them,
#: the observation statistics as arrays, and as older runs pickled them.
ARTIFACT_CONFIG = "config.json"
ARTIFACT_MODEL = "model.zip"
ARTIFACT_POLICY = "policy.pth"
ARTIFACT_NORMALIZER = "vecnormalize.npz"
ARTIFACT_PICKLED_NORMALIZER = "vecnormalize.pkl"

# ---- tags every vlmrl run carries (store.provenance_tags) ------------------------------------
TAG_VLM = f"{TAG_PREFIX}vlm"
TAG_SIMULATED = f"{TAG_PREFIX}simulated"  # "true" / "false"
TAG_GIT_COMMIT = f"{TAG_PREFIX}git_commit"
TAG_VERSION_PREFIX = f"{TAG_PREFIX}version."  # + package name
TAG_CPU_PREFIX = f"{TAG_PREFIX}cpu."  # + numpy_simd / blas / torch / model
TAG_PIN = f"{TAG_PREFIX}pin"  # core.numeric_pin.PIN_ID, or "unpinned"
TAG_PIN_ENV = f"{TAG_PREFIX}pin.env"  # the pin variables' values in force
TAG_NOTE = f"{TAG_PREFIX}note"  # set only on runs of the simulated VLM

# ---- what a run is -----------------------------------------------------------------------------
TAG_KIND = f"{TAG_PREFIX}kind"
KIND_TRAIN = "train"
KIND_SWEEP = "sweep"
KIND_REPORT = "report"
KIND_CALIBRATION = "calibration"
KIND_STUDY = "study"
TAG_COMMAND = f"{TAG_PREFIX}command"  # taxonomy runs carry this instead of a kind
COMMAND_TAXONOMY = "taxonomy"

# ---- training runs (and sweeps) ----------------------------------------------------------------
TAG_ARM = f"{TAG_PREFIX}arm"
TAG_SEED = f"{TAG_PREFIX}seed"
TAG_CONFIG_HASH = f"{TAG_PREFIX}config_hash"
TAG_PRESET = f"{TAG_PREFIX}preset"
TAG_OVERRIDES = f"{TAG_PREFIX}overrides"  # "key=value ..." or "none"
TAG_REGIME = f"{TAG_PREFIX}regime"
TAG_SCALES = f"{TAG_PREFIX}scales"  # a shaped arm's alpha and kin_scale and where they came from (issue 41)
TAG_TASK = f"{TAG_PREFIX}task"  # the run's task (--task); runs from before tasks have none: mountain-car
TAG_SIM_PROFILE = f"{TAG_PREFIX}sim_profile"
TAG_PLACEBO_MAP = f"{TAG_PREFIX}placebo_map"  # a placebo arm's shuffled label map, "LABEL=phi ..."
TAG_STOCHASTIC_VLM = f"{TAG_PREFIX}stochastic_vlm"  # "true": answers drawn afresh per query, never cached
TAG_EPISODES_TABLE = f"{TAG_PREFIX}episodes_table"  # artifact name of the per-episode table, if written
TAG_ERROR = f"{TAG_PREFIX}error"
TAG_TRACEBACK = f"{TAG_PREFIX}traceback"
TAG_OWNER = f"{TAG_PREFIX}owner"  # "host:pid" of the process training the run
TAG_HEARTBEAT = f"{TAG_PREFIX}heartbeat"  # Unix seconds, refreshed while the run trains
TAG_EXECUTOR = f"{TAG_PREFIX}executor"  # on sweep runs: local or ray

# ---- report runs -------------------------------------------------------------------------------
TAG_REPORT_EXPERIMENT = f"{TAG_PREFIX}report.experiment"
TAG_REPORT_KEY = f"{TAG_PREFIX}report.key"
TAG_REPORT_RUNS = f"{TAG_PREFIX}report.runs"

# ---- MLflow's own tags -------------------------------------------------------------------------
MLFLOW_RUN_NAME = "mlflow.runName"
MLFLOW_PARENT_RUN_ID = "mlflow.parentRunId"
MLFLOW_GIT_COMMIT = "mlflow.source.git.commit"

# ---- params ------------------------------------------------------------------------------------
PARAM_TIMESTEPS = "timesteps"

# ---- metrics: training episodes (step = global timestep at the episode's end) -------------------
METRIC_NATIVE_RETURN = "episode/native_return"
METRIC_LENGTH = "episode/length"
METRIC_SUCCESS = "episode/success"
METRIC_SHAPED_RETURN = "episode/shaped_return"
EPISODE_METRICS = (METRIC_NATIVE_RETURN, METRIC_LENGTH, METRIC_SUCCESS, METRIC_SHAPED_RETURN)

# ---- metrics: at each rollout end (step = global timestep) --------------------------------------
METRIC_RETURN_100 = "rollout/return_100"  # mean native return of the last 100 episodes
METRIC_STEPS_PER_S = "perf/steps_per_s"
METRIC_VLM_QUERIES = "vlm/queries"
METRIC_VLM_CACHE_HITS = "vlm/cache_hits"
METRIC_VLM_PROTOTYPES = "vlm/prototypes"
METRIC_VLM_LABEL_REUSES = "vlm/label_reuses"
METRIC_VLM_PARSE_FAILURES = "vlm/parse_failures"
#: What the VLM cost a run (issue 53): backend calls (one per labelling round with a miss), their
#: frames, the largest round, the seconds waited and their share of wall time, and the labels taken
#: from the nearest prototype once ``vlm.max_queries`` was spent.
METRIC_VLM_BACKEND_CALLS = "vlm/backend_calls"
METRIC_VLM_BACKEND_FRAMES = "vlm/backend_frames"
METRIC_VLM_LARGEST_BATCH = "vlm/largest_batch"
METRIC_VLM_BACKEND_S = "vlm/backend_s"
METRIC_VLM_WAIT_SHARE = "vlm/wait_share"
METRIC_VLM_BUDGET_LABELS = "vlm/budget_labels"
#: How the backend answered: from the MCQ options' log-probabilities, or by generating text.
METRIC_VLM_SCORED = "vlm/scored"
METRIC_VLM_GENERATED = "vlm/generated"
#: SB3's PPO update diagnostics (``train/approx_kl``, ...), forwarded under this prefix.
TRAIN_METRIC_PREFIX = "train/"

# ---- metrics: detached evaluation (summary at step 0; per episode stepped by its index) ---------
METRIC_EVAL_SUCCESS_RATE = "eval/success_rate"
METRIC_EVAL_MEAN_LENGTH = "eval/mean_length"
METRIC_EVAL_MEAN_RETURN = "eval/mean_return"
METRIC_EVAL_HOVER_FRACTION = "eval/hover_fraction"
METRIC_EVAL_DWELL_RIGHT_STEPS = "eval/dwell_right_steps"
METRIC_EVAL_EPISODE_RETURN = "eval/episode_return"
METRIC_EVAL_EPISODE_LENGTH = "eval/episode_length"
METRIC_EVAL_EPISODE_SUCCESS = "eval/episode_success"

# ---- metrics: wall time ------------------------------------------------------------------------
METRIC_WALL_S = "perf/wall_s"  # a training run's, at step = its budget
METRIC_SWEEP_WALL_S = "perf/sweep_wall_s"  # on the sweep's parent run

#: Runs per ``search_runs`` call in ``search_all``.
PAGE_SIZE = 1000


def runs_filter(tags: Mapping[str, str], finished: bool = False) -> str:
    """An MLflow ``filter_string`` matching every tag of ``tags`` (and status FINISHED if asked)."""
    terms = [f"tags.`{key}` = '{value}'" for key, value in tags.items()]
    if finished:
        terms.append("attributes.status = 'FINISHED'")
    return " and ".join(terms)


def job_key(tags: Mapping[str, str]) -> tuple[str, str, str]:
    """The job a training run trains, ``(arm, seed, config_hash)`` as its tags spell them ("" where absent).

    Example:
        >>> job_key({TAG_ARM: "hybrid", TAG_SEED: "3", TAG_CONFIG_HASH: "ab12"})
        ('hybrid', '3', 'ab12')
    """
    return tags.get(TAG_ARM, ""), tags.get(TAG_SEED, ""), tags.get(TAG_CONFIG_HASH, "")


def train_runs_by_job(client: Any, experiment_id: str) -> dict[tuple[str, str, str], list[Any]]:
    """The experiment's training runs by ``job_key``, each job's in search order."""
    by_key: dict[tuple[str, str, str], list[Any]] = {}
    for run in search_all(client, experiment_id, runs_filter({TAG_KIND: KIND_TRAIN})):
        by_key.setdefault(job_key(run.data.tags), []).append(run)
    return by_key


def finished_train_runs(client: Any, experiment: str) -> list[Any]:
    """The FINISHED training runs of ``experiment``, oldest first; ``BadInput`` when it does not exist."""
    exp = client.get_experiment_by_name(experiment)
    if exp is None or exp.lifecycle_stage == "deleted":
        raise BadInput(f"MLflow experiment '{experiment}' does not exist in this store; pass --experiment NAME.")
    runs = search_all(client, exp.experiment_id, runs_filter({TAG_KIND: KIND_TRAIN}, finished=True))
    return sorted(runs, key=lambda r: (r.info.start_time or 0, r.info.run_id))


def search_all(client: Any, experiment_id: str, filter_string: str, page_size: int = PAGE_SIZE) -> list[Any]:
    """Every run of ``experiment_id`` that matches ``filter_string``, following MLflow's page tokens."""
    runs: list[Any] = []
    token: str | None = None
    while True:
        page = client.search_runs([experiment_id], filter_string=filter_string, max_results=page_size,
                                  page_token=token)
        runs.extend(page)
        token = page.token
        if not token:
            return runs
