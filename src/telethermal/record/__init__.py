"""Session recordings: MCAP files with msgpack-encoded channels."""
