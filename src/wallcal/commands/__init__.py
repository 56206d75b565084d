"""CLI commands, one module each; shared formatting helpers in :mod:`._format`."""
