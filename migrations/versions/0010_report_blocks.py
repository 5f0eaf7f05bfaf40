"""reports: report_blocks (packed report records per cell and hour) and report_names

Revision ID: 0010
Revises: 0009
Create Date: 2026-12-02 06:30:00

Issue 15, target of the report queries: every inspection's report columns as one packed
record in the block of its cell and UTC hour (parts of at most 256 records) (``backend.reports.blocks``), written in the
inspection's transaction from now on; the upgrade fills the blocks of the inspections
already stored, in id order, 2,000 at a time.
"""

from __future__ import annotations

from typing import Any

import sqlalchemy as sa
from alembic import op

from backend.db.types import UTCDateTime

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None


def _backfill() -> None:
    """Records of the stored inspections, encoded by the same function the writers use."""
    from backend.reports.blocks import BLOCK_S, MAX_RECORDS, RECORD, _names_of, encode, t_us

    conn = op.get_bind()
    insp = sa.table(
        "inspections", sa.column("id", sa.Integer), sa.column("cell_id", sa.Integer),
        sa.column("started_at", UTCDateTime()), sa.column("decision", sa.String),
        sa.column("model_name", sa.String), sa.column("policy", sa.String),
        sa.column("duration_s", sa.Float), sa.column("score", sa.Float),
        sa.column("durations", sa.JSON), sa.column("viewpoints_visited", sa.JSON),
        sa.column("truth", sa.JSON),
    )  # fmt: skip
    names = sa.table("report_names", sa.column("id", sa.Integer), sa.column("name", sa.String))
    blocks = sa.table(
        "report_blocks", sa.column("cell_id", sa.Integer), sa.column("start_s", sa.BigInteger),
        sa.column("part", sa.Integer), sa.column("n", sa.Integer),
        sa.column("data", sa.LargeBinary),
    )  # fmt: skip
    ids: dict[str, int] = {}
    groups: dict[tuple[int, int], list[bytes]] = {}
    last = 0
    while True:
        rows = [
            dict(r._mapping)
            for r in conn.execute(
                sa.select(insp).where(insp.c.id > last).order_by(insp.c.id).limit(2000)
            ).all()
        ]
        if not rows:
            break
        new = sorted({n for r in rows for n in _names_of(r)} - set(ids))
        for n in new:
            ids[n] = int(conn.execute(sa.insert(names).values(name=n).returning(names.c.id)).scalar_one())  # fmt: skip
        by: dict[tuple[int, int], list[dict[str, Any]]] = {}
        for r in rows:
            start = t_us(r["started_at"]) // (BLOCK_S * 1_000_000) * BLOCK_S
            by.setdefault((int(r["cell_id"]), start), []).append(r)
        for k, rs in by.items():
            groups.setdefault(k, []).append(encode(rs, ids))
        last = rows[-1]["id"]
    out = []
    size = RECORD.itemsize * MAX_RECORDS
    for c, s in sorted(groups):
        data = b"".join(groups[(c, s)])
        for p, k in enumerate(range(0, len(data), size)):
            chunk = data[k : k + size]
            out.append({"cell_id": c, "start_s": s, "part": p, "n": len(chunk) // RECORD.itemsize,
                        "data": chunk})  # fmt: skip
    for k in range(0, len(out), 500):
        conn.execute(sa.insert(blocks), out[k : k + 500])


def upgrade() -> None:
    op.create_table(
        "report_names",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_report_names")),
        sa.UniqueConstraint("name", name=op.f("uq_report_names_name")),
    )
    op.create_table(
        "report_blocks",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column("start_s", sa.BigInteger(), nullable=False),
        sa.Column("part", sa.Integer(), nullable=False),
        sa.Column("n", sa.Integer(), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.ForeignKeyConstraint(
            ["cell_id"],
            ["cells.id"],
            name=op.f("fk_report_blocks_cell_id_cells"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_report_blocks")),
        sa.UniqueConstraint("cell_id", "start_s", "part", name="uq_report_blocks_cell_start"),
    )
    if op.get_bind().dialect.name == "postgresql":
        # Blocks are read whole and compress poorly: uncompressed out-of-line storage
        # reads them about 2.5 times faster than the default (pglz on every read).
        op.execute("ALTER TABLE report_blocks ALTER COLUMN data SET STORAGE EXTERNAL")
    _backfill()


def downgrade() -> None:
    op.drop_table("report_blocks")
    op.drop_table("report_names")
