"""Alembic migrations of the soakcal schema, kept in the package for installed services."""
