"""The wire protocol between master and slave: schema, codec, transport."""
