"""``kinemaforge batch``: many inputs in parallel on Ray, one failure never stops the rest."""

from .jobs import JOBS, diagnose_job
from .runner import BatchItem, run_batch, summary_table

__all__ = ["JOBS", "BatchItem", "diagnose_job", "run_batch", "summary_table"]
