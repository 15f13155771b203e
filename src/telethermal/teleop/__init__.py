"""Telepresence sessions: the slave, the master, and a session joining them."""
