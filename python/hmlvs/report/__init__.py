"""Reports: the self-contained HTML calibration report."""
