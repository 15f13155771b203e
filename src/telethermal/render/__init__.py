"""Rendering: flux generation (and, later, latency compensation)."""
