"""The simulator: what stands in for the lab's hardware and the world it touches."""
