"""Mechanisms of the case studies. Each module exposes its kinematics as pure JAX functions."""
