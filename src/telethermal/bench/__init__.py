"""Benchmarks: speed against error."""
