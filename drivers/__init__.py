"""soakcal drivers package."""
