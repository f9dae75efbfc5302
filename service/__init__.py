"""soakcal service package."""
