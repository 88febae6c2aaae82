"""The trial metadata parknss writes into its own files (Parquet key, CSV comment,
.mat variable, MDF4 header comment), and its reader."""

from __future__ import annotations

import json
from pathlib import Path

from parknss.errors import DataError
from parknss.signals import SCHEMA_VERSION

META_KEY = "parknss_trial"  # trial metadata: Parquet schema key, CSV comment, .mat variable


def parse_meta(text: str | bytes, source: Path) -> dict:
    """The metadata JSON object; DataError if it is not one or of another schema version."""
    try:
        meta = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{source}: trial metadata {META_KEY!r} is not valid JSON") from exc
    if not isinstance(meta, dict):
        raise DataError(f"{source}: trial metadata {META_KEY!r} is not a JSON object")
    version = str(meta.get("schema_version", SCHEMA_VERSION))
    if version != SCHEMA_VERSION:
        raise DataError(
            f"{source}: written with schema version {version!r}, this parknss reads "
            f"{SCHEMA_VERSION!r}"
        )
    return meta
