"""Optimisation problems: a design box and a swarm-evaluating objective."""

from designopt.problems.base import Problem

__all__ = ["Problem"]
