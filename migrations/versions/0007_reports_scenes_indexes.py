"""reports: inspection_scenes (3D scene recordings), inspection_stages and report indexes

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-02 03:00:00

Issue 15, parts 3, 4 and 6: the viser scene recorded during an inspection, one row per
inspection; the per-stage seconds of every inspection as rows (filled from
``inspections.durations`` for the rows already there); indexes the report percentiles walk
(``benchmarks/reports.py``).
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from backend.db.types import UTCDateTime

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


_STAGE_KEYS = 16  # at most this many stages per inspection are copied


def _backfill() -> None:
    """Copy ``inspections.durations`` into ``inspection_stages`` (both engines: in Python)."""
    conn = op.get_bind()
    insp = sa.table(
        "inspections", sa.column("id", sa.Integer), sa.column("cell_id", sa.Integer),
        sa.column("started_at", UTCDateTime()), sa.column("decision", sa.String),
        sa.column("model_name", sa.String), sa.column("policy", sa.String),
        sa.column("durations", sa.JSON),
    )  # fmt: skip
    stages = sa.table(
        "inspection_stages", sa.column("inspection_id", sa.Integer), sa.column("stage", sa.String),
        sa.column("seconds", sa.Float), sa.column("cell_id", sa.Integer),
        sa.column("started_at", UTCDateTime()), sa.column("decision", sa.String),
        sa.column("model_name", sa.String), sa.column("policy", sa.String),
    )  # fmt: skip
    last = 0
    while True:
        rows = conn.execute(
            sa.select(insp).where(insp.c.id > last).order_by(insp.c.id).limit(2000)
        ).all()
        if not rows:
            return
        out = []
        for r in rows:
            for k, v in list((r.durations or {}).items())[:_STAGE_KEYS]:
                if isinstance(v, int | float) and not isinstance(v, bool) and 0 <= v < 1e6:
                    out.append({"inspection_id": r.id, "stage": str(k)[:16], "seconds": float(v),
                                "cell_id": r.cell_id, "started_at": r.started_at,
                                "decision": r.decision, "model_name": r.model_name,
                                "policy": r.policy})  # fmt: skip
        if out:
            conn.execute(sa.insert(stages), out)
        last = rows[-1].id


def upgrade() -> None:
    op.create_table(
        "inspection_stages",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("inspection_id", sa.Integer(), nullable=False),
        sa.Column("stage", sa.String(length=16), nullable=False),
        sa.Column("seconds", sa.Float(), nullable=False),
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column("started_at", UTCDateTime(), nullable=False),
        sa.Column("decision", sa.String(length=16), nullable=False),
        sa.Column("model_name", sa.String(length=64), nullable=True),
        sa.Column("policy", sa.String(length=16), nullable=False),
        sa.ForeignKeyConstraint(
            ["inspection_id"],
            ["inspections.id"],
            name=op.f("fk_inspection_stages_inspection_id_inspections"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_inspection_stages")),
    )
    op.create_index(
        op.f("ix_inspection_stages_inspection_id"), "inspection_stages", ["inspection_id"]
    )
    _backfill()
    op.create_index("ix_inspection_stages_stage_seconds", "inspection_stages", ["stage", "seconds"])
    op.create_index(
        "ix_inspection_stages_stage_cell_time",
        "inspection_stages",
        ["stage", "cell_id", "started_at"],
    )
    op.create_index(
        "ix_inspection_stages_stage_model", "inspection_stages", ["stage", "model_name", "seconds"]
    )
    op.create_index("ix_inspections_report_duration", "inspections", ["duration_s"])
    op.create_index("ix_inspections_report_model_score", "inspections", ["model_name", "score"])
    op.create_index("ix_inspections_report_cell_time", "inspections", ["cell_id", "started_at"])
    op.create_table(
        "inspection_scenes",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("inspection_id", sa.Integer(), nullable=False),
        sa.Column("scene", sa.LargeBinary(), nullable=False),
        sa.Column("size_bytes", sa.Integer(), nullable=False),
        sa.Column("created_at", UTCDateTime(), nullable=False),
        sa.ForeignKeyConstraint(
            ["inspection_id"],
            ["inspections.id"],
            name=op.f("fk_inspection_scenes_inspection_id_inspections"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_inspection_scenes")),
        sa.UniqueConstraint("inspection_id", name=op.f("uq_inspection_scenes_inspection_id")),
    )


def downgrade() -> None:
    op.drop_table("inspection_scenes")
    op.drop_index("ix_inspections_report_cell_time", table_name="inspections")
    op.drop_index("ix_inspections_report_model_score", table_name="inspections")
    op.drop_index("ix_inspections_report_duration", table_name="inspections")
    op.drop_index("ix_inspection_stages_stage_model", table_name="inspection_stages")
    op.drop_index("ix_inspection_stages_stage_cell_time", table_name="inspection_stages")
    op.drop_index("ix_inspection_stages_stage_seconds", table_name="inspection_stages")
    op.drop_index(op.f("ix_inspection_stages_inspection_id"), table_name="inspection_stages")
    op.drop_table("inspection_stages")
