"""Composition of the frog packages: the digital twin, the in-process evaluator, shared metrics and plots."""
