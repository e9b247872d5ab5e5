"""`vlmrl evaluate`: a trained run's success rate, and a captioned GIF of one of its episodes."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from vlmrl_cli.cli.options import CachePath, TrackingUri, TrustPickle, UseCache, UserTasks
from vlmrl_cli.vlm.config import DEFAULT_CACHE

EvalOut = Annotated[Path | None, typer.Option(
    "--out", help="Output folder (default: results/_scratch/evaluate/RUN_ID, git-ignored, so that no committed "
                  "result is overwritten unless named here).", show_default=False)]

if TYPE_CHECKING:
    from vlmrl_cli.report.children import ChildRow

#: The first line of the output of a run that used the simulated VLM.
SIMULATED_NOTICE = ("WARNING: SIMULATED VLM (not a real model): the GIF's VLM labels come from a pixel reader "
                    "with noise.")


def pick_child(run_id: str, children: Sequence[ChildRow], arm: str | None, seed: int | None) -> str:
    """The run id of the child of ``arm`` and ``seed`` of the sweep's parent run ``run_id``, or
    ``BadInput`` that says what to give and lists the children."""
    from vlmrl_cli.core.errors import BadInput

    picked = [c for c in children if (arm is None or c.arm == arm) and (seed is None or c.seed == seed)]
    if arm is not None and seed is not None and len(picked) == 1:
        return picked[0].run_id

    def listing(rows: Sequence[ChildRow]) -> str:
        return ", ".join(f"{c.arm} seed {c.seed} = {c.run_id}" for c in rows) or "none it trained itself"

    given = " and ".join(part for part in (f"arm {arm}" if arm is not None else "",
                                           f"seed {seed}" if seed is not None else "") if part)
    if given and not picked:
        raise BadInput(f"run {run_id} is a sweep's parent run with no training run of {given}; pass the --arm and "
                       f"--seed of one of its training runs: {listing(children)}.")
    if arm is not None and seed is not None:  # the sweep trained that job more than once (a retried attempt)
        raise BadInput(f"run {run_id} is a sweep's parent run with {len(picked)} training runs of {given}: "
                       f"{listing(picked)}; pass the run id of the one to evaluate.")
    missing = " ".join(flag for flag, value in (("--arm ARM", arm), ("--seed N", seed)) if value is None)
    raise BadInput(f"run {run_id} is a sweep's parent run, not a training run; pass {missing}, or one of its "
                   f"training runs: {listing(picked or children)} (`vlmrl run ... --dry-run` lists every job's run).")


def resolve_child(run_id: str, tracking_uri: str | None, arm: str | None, seed: int | None) -> str:
    """``run_id`` for a training run; for a sweep's parent run, its child of ``--arm``/``--seed``."""
    from vlmrl_cli.core.errors import BadInput
    from vlmrl_cli.tracking import schema, store

    client = store.connect_existing(tracking_uri)  # checked before MLflow loads (a second)
    from mlflow.exceptions import MlflowException

    from vlmrl_cli.report.children import children_of

    try:
        run = client.get_run(run_id)
    except MlflowException:
        return run_id  # evaluate_run says there is no such run
    if run.data.tags.get(schema.TAG_KIND) != schema.KIND_SWEEP:
        if arm is not None or seed is not None:
            raise BadInput(f"--arm/--seed pick a child of a sweep's parent run; run {run_id} is a training run "
                           "already: drop them.")
        return run_id
    return pick_child(run_id, children_of(client, run), arm, seed)


def evaluate(
    run_id: Annotated[str, typer.Argument(help="MLflow run id of a finished training run (`vlmrl run` prints them).")],
    episodes: Annotated[int, typer.Option("--episodes", min=1, help="Detached evaluation episodes.")] = 10,
    episode_index: Annotated[
        int, typer.Option("--episode-index", min=0, help="Which evaluated episode the GIF shows.")
    ] = 0,
    out: EvalOut = None,
    tracking_uri: TrackingUri = None,
    use_cache: UseCache = True,
    cache_path: CachePath = DEFAULT_CACHE,
    arm: Annotated[str | None, typer.Option("--arm", help="With a sweep's parent run id: the arm of the child "
                                                          "run to evaluate.")] = None,
    seed: Annotated[int | None, typer.Option("--seed", help="With a sweep's parent run id: the seed of the child "
                                                           "run to evaluate.")] = None,
    user_task: UserTasks = None,
    trust_pickle: TrustPickle = False,
) -> None:
    """Evaluate a trained policy on its task's native environment and write a captioned GIF of one episode.

    Outputs go to --out (default results/_scratch/evaluate/RUN_ID/, git-ignored) and to the run's
    MLflow artifacts under evaluate/.
    """
    from vlmrl_cli.tasks.registry import command_tasks
    from vlmrl_cli.training.evaluate_trained import EvaluateConfig, evaluate_run

    tasks = command_tasks(user_task or ())
    cfg = EvaluateConfig(run_id=run_id, tracking_uri=tracking_uri, out=out, episodes=episodes,
                         episode_index=episode_index, use_cache=use_cache, cache_path=cache_path,
                         trust_pickle=trust_pickle)
    cfg.validate()  # the flags, before the store is opened
    cfg = dataclasses.replace(cfg, run_id=resolve_child(run_id, tracking_uri, arm, seed))
    done = evaluate_run(cfg, tasks)

    run = done.run
    if run.arm.uses_vlm and run.simulated:  # first, and on the results' own stream: no capture can reorder them
        typer.secho(SIMULATED_NOTICE, fg=typer.colors.YELLOW)
    typer.echo(f"run:       {run.name} ({run.run_id}, arm {run.arm.name}, {run.status})")
    typer.echo(f"evaluated: {cfg.episodes} native episodes: success rate {done.result.success_rate:.0%}, "
               f"mean length {done.result.mean_length:.1f}, mean return {done.result.mean_return:.1f}")
    typer.echo(f"GIF:       {done.gif} (episode {cfg.episode_index}, {done.frames} frames, "
               f"{done.gif_bytes / 1024:.0f} KiB)")
    typer.echo(f"figures:   {done.summary}")
    typer.echo(f"MLflow:    logged under {run.run_id}/artifacts/evaluate/")
