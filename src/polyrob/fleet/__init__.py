"""Many robots at once: batch runs locally or on a Dask cluster, and automatic weights.

* :func:`run_batch` (:mod:`polyrob.fleet.batch`) - the pipeline for a list of
  robots and variants, in spawned worker processes or on a Dask distributed
  cluster; per-robot files and a summary table.
* :func:`automatic_hyperparameters` (:mod:`polyrob.fleet.autoweights`) -
  default W_S / W_T for any joint count and domain, in the paper's shape.
* :class:`Job`, :class:`Settings`, :class:`RobotResult`, :func:`run_job`
  (:mod:`polyrob.fleet.jobs`) - one robot's unit of work.
"""

from polyrob.fleet.autoweights import automatic_hyperparameters, domain_level
from polyrob.fleet.batch import SERIAL_ARMS, BatchResult, run_batch, serial_arms
from polyrob.fleet.jobs import Job, RobotResult, Settings, run_job

__all__ = [
    "run_batch",
    "BatchResult",
    "SERIAL_ARMS",
    "serial_arms",
    "automatic_hyperparameters",
    "domain_level",
    "Job",
    "Settings",
    "RobotResult",
    "run_job",
]
