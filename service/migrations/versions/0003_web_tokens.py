"""API tokens: optional expiry and revocation (issue 13, branch web).

Revision ID: 0003_web_tokens
Revises: 0002
Create Date: 2026-11-23 04:00:00
"""

from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = "0003_web_tokens"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("api_tokens") as batch:  # batch: SQLite cannot ALTER freely
        batch.add_column(sa.Column("expires_at", sa.DateTime(timezone=True), nullable=True))
        batch.add_column(sa.Column("revoked_at", sa.DateTime(timezone=True), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("api_tokens") as batch:
        batch.drop_column("revoked_at")
        batch.drop_column("expires_at")
