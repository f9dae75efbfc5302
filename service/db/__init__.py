"""Persistence: SQLAlchemy 2.x models and session handling (schema owned by Alembic)."""
