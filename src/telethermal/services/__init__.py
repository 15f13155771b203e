"""The master and slave as separate networked processes."""
