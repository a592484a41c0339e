"""Optimizers behind one protocol (protocol.py): the PSO family p1..p7 (PTPSO = p3) as one
entry, CMA-ES beside it, and the runner that vmaps runs and settings over any of them.

The pipeline's interface: ``run``, ``run_batch``, ``validate``, ``setting_names``,
``names``/``OPTIMIZERS``, ``RunResult``, ``Checkpoint`` (docs/optimizers.md).
"""

from designopt.optim.protocol import Best, Optimizer, Task
from designopt.optim.pso import constriction, penalty_coefficient
from designopt.optim.registry import (
    OPTIMIZERS,
    make_params,
    names,
    option_names,
    resolve,
    setting_names,
    validate,
)
from designopt.optim.runner import Checkpoint, RunResult, convergence_iteration, run, run_batch

__all__ = [
    "OPTIMIZERS",
    "Best",
    "Checkpoint",
    "Optimizer",
    "RunResult",
    "Task",
    "constriction",
    "convergence_iteration",
    "make_params",
    "names",
    "option_names",
    "penalty_coefficient",
    "resolve",
    "run",
    "run_batch",
    "setting_names",
    "validate",
]
