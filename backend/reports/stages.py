"""The per-stage rows of an inspection (``inspection_stages``): ``inspections.durations`` as
one row per stage, with the columns the reports filter on, written with the inspection."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["MAX_STAGES", "STAGES", "stage_rows"]

#: Stages of an inspection as ``backend.inspection.service`` times them (``durations`` keys).
STAGES = ("wait", "move", "settle", "acquire", "segment", "features", "match", "plan", "decide",
          "pose", "pick")  # fmt: skip

#: At most this many stages of one inspection are stored as rows.
MAX_STAGES = 16


def stage_rows(inspection_id: int, row: dict[str, Any]) -> list[dict[str, Any]]:
    """Rows for ``insert(InspectionStage)`` from an inspection's column values (``row``: its
    ``cell_id``, ``started_at``, ``decision``, ``model_name``, ``policy``, ``durations``);
    non-finite or negative seconds are left out."""
    out = []
    dec = row["decision"]
    for k, v in list((row.get("durations") or {}).items())[:MAX_STAGES]:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
            continue
        out.append({
            "inspection_id": inspection_id, "stage": str(k)[:16], "seconds": float(v),
            "cell_id": row["cell_id"], "started_at": row["started_at"],
            "decision": getattr(dec, "value", dec), "model_name": row.get("model_name"),
            "policy": row["policy"],
        })  # fmt: skip
    return out
