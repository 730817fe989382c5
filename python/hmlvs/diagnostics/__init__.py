"""What a calibration determines: identifiability, uncertainty and repeatability."""
