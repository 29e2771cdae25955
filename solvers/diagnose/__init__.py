"""Diagnosis: what the fitted baseline model gets wrong on measured data, which named effect
explains it, and what the extended model gains (../shared/spec/diagnose.md)."""

from solvers.diagnose.engine import Candidate, Diagnosis, Problem, diagnose

__all__ = ["Candidate", "Diagnosis", "Problem", "diagnose"]
