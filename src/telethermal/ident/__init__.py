"""Material identification from the first fraction of a second of contact."""
