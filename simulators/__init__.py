"""soakcal simulators package."""
