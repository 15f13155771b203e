"""telethermal: thermal telepresence, from contact physics to heat-flux rendering."""

__version__ = "0.1.0"
