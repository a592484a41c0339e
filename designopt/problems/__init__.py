"""Optimisation problems: a design box and a swarm-evaluating objective."""

from designopt.problems.base import Problem
from designopt.problems.benchmarks import FUNCTIONS, benchmark

__all__ = ["FUNCTIONS", "Problem", "benchmark"]
