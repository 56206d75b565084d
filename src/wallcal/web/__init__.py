"""The manual-calibration web page (``wallcal serve``)."""
