"""Reports over the stored inspections: exact aggregations over
the packed report blocks (:mod:`backend.reports.blocks`, :mod:`backend.reports.queries`;
the raw-row SQL in :mod:`backend.reports.sql`) that answer the same on SQLite and
PostgreSQL, streamed exports, plots, image retention and the 3D scene recordings of
inspections."""

from backend.reports.export import FIELDS, check_export, export_csv, export_jsonl, export_rows
from backend.reports.filters import ReportFilters, make_filters
from backend.reports.queries import STAGES, confusion, summary, timeseries
from backend.reports.retention import PruneResult, keeps_images, prune, prune_loop, storage_used
from backend.reports.scenes import SceneRecorder, read_scene

__all__ = [
    "FIELDS",
    "STAGES",
    "PruneResult",
    "ReportFilters",
    "SceneRecorder",
    "check_export",
    "confusion",
    "export_csv",
    "export_jsonl",
    "export_rows",
    "keeps_images",
    "make_filters",
    "prune",
    "prune_loop",
    "read_scene",
    "storage_used",
    "summary",
    "timeseries",
]
