"""Datasets: the on-disk format, generation of the two databases, plots."""
