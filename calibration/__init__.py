"""soakcal calibration package."""
