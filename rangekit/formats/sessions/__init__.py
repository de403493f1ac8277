"""Scan sessions on disk: session.json (the only reader), its field checks, the frames' SHA-256 check, the
one-process lock, the object entry, and summary.json."""
