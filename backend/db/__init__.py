"""Database: models, engine and migrations."""

from backend.db.models import Base
from backend.db.session import Database
from backend.db.types import UTCDateTime, utcnow

__all__ = ["Base", "Database", "UTCDateTime", "utcnow"]
