"""Files and data sets: calibration data sets, image manifests, calibration files."""
