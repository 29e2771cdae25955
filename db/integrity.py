"""Tamper evidence: each calibration row carries sha256 of its content and the previous hash.

`hash = sha256(canonical JSON of every column of the row except `hash`)`, where the
row includes `prev_hash` (the hash of the same device's previous calibration, by id;
NULL for its first) and `capture_sha256` (the digest of the stored samples). Editing
any stored field, a capture's samples, or deleting/inserting a record in the middle
of a device's history is then visible to `Store.verify()`. It detects edits made
with ordinary tools; it is not a signature (someone who rewrites every later hash
with this code cannot be caught from inside the file).
"""

from __future__ import annotations

import hashlib
import json

# Columns of `calibrations` that form the hashed content (everything but `hash`).
HASHED_COLUMNS = (
    "id",
    "device_id",
    "procedure",
    "time",
    "model",
    "params",
    "uncertainty",
    "residual_rms",
    "n_positions",
    "warnings",
    "result_extra",
    "software_version",
    "capture_id",
    "capture_sha256",
    "operator",
    "host",
    "accepted",
    "supersedes",
    "saved_at",
    "record_version",
    "prev_hash",
)


# Added by record_version 2 (hashed only in rows of that version or later, so rows
# written before keep their hash).
HASHED_COLUMNS_V2 = ("review",)


def record_hash(row: dict) -> str:
    content = {k: row.get(k) for k in HASHED_COLUMNS}
    if (row.get("record_version") or 1) >= 2:
        content.update({k: row.get(k) for k in HASHED_COLUMNS_V2})
    text = json.dumps(content, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


# Columns of `anchors` that form an anchor's hash (everything but `hash`).
ANCHOR_COLUMNS = (
    "id",
    "time",
    "device_id",
    "event",
    "head_id",
    "head_hash",
    "n_calibrations",
    "settings_hash",
    "capture_id",
    "prev_hash",
)
# Device columns under the anchors (everything a person could change to move a due date or
# loosen a tolerance). Settings version 2 (migration 0004_limits_anchored) adds the absolute
# limits; its hashes are written ``2:<hex>``, so an anchor says which columns it covers and
# anchors written before keep verifying.
SETTINGS_COLUMNS = ("id", "model", "sensor_kinds", "notes", "interval_days", "tolerances", "created")
SETTINGS_COLUMNS_V2 = ("limits",)
SETTINGS_VERSION = 2


def _digest(content: dict) -> str:
    text = json.dumps(content, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def anchor_hash(row: dict) -> str:
    return _digest({k: row.get(k) for k in ANCHOR_COLUMNS})


def settings_hash(device_row: dict, version: int = SETTINGS_VERSION) -> str:
    """The hash of a device's settings as an anchor stores it: version 1 (the bare hex
    digest) covers ``SETTINGS_COLUMNS``, version 2 (``2:<hex>``) the limits too."""
    content = {k: device_row.get(k) for k in SETTINGS_COLUMNS}
    if version < 2:
        return _digest(content)
    content.update({k: device_row.get(k) for k in SETTINGS_COLUMNS_V2})
    return f"{version}:{_digest(content)}"


def settings_version(stored_hash: str) -> int:
    """The settings version an anchor's ``settings_hash`` was written with (1: no prefix)."""
    head, sep, _ = (stored_hash or "").partition(":")
    return int(head) if sep and head.isdigit() else 1
