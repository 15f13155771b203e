"""Fault injection: a faulty network between master and slave."""
