"""What ``daa-sil run`` writes into its output directory: the names (:data:`RUN_FILES`), ``--force``'s
removal of a previous run's outputs, and the step log the vehicle saved elsewhere when the directory
could no longer take it (:func:`daa_sil.out_dir.write_or_rescue`)."""

from __future__ import annotations

from pathlib import Path


def rescued_steplog(steplog: Path, since: float) -> "Path | None":
    """The step log the vehicle saved at :func:`daa_sil.out_dir.rescue_path` because ``steplog``'s
    directory could not take it (written after ``since``, a wall time), or None."""
    from daa_sil.out_dir import rescue_path  # lazy: start-up time

    if steplog.exists():
        return None
    alt = rescue_path(steplog)
    try:
        return alt if alt.stat().st_mtime >= since - 1.0 else None
    except OSError:
        return None


#: what ``daa-sil run`` writes into its output directory (``--force`` removes these and nothing else)
RUN_FILES = ("result.json", "steplog.parquet", "shim_stats.json", "gcs_commands.jsonl")


def remove_run_outputs(out: Path) -> None:
    """``--force``: remove a previous run's outputs from ``out`` (:data:`RUN_FILES`, the restarted GCSs'
    command logs, the processes' logs); anything else stays."""
    for name in RUN_FILES:
        (out / name).unlink(missing_ok=True)
    for f in out.glob("gcs_commands_*.jsonl"):
        f.unlink(missing_ok=True)
    logs = out / "logs"
    if logs.is_dir():
        for f in logs.glob("*.log"):
            f.unlink(missing_ok=True)
        try:
            logs.rmdir()
        except OSError:  # something else is in there: it stays
            pass


__all__ = ["RUN_FILES", "rescued_steplog", "remove_run_outputs"]
