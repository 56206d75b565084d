"""CLI commands, one module each; tables are rendered by :mod:`wallcal.formatting`."""
