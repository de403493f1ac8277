"""The headers every response of ``rangekit ui`` carries, and the Content-Security-Policy of each kind of page.

- every response: ``X-Content-Type-Options: nosniff``, ``Referrer-Policy: no-referrer``,
  ``Cross-Origin-Resource-Policy: same-origin`` (another site's ``<img>`` or ``<script>`` gets nothing);
- the app's page: a CSP allowing only its own scripts (and its inline import map, by hash), its own
  connections, images from itself or blob URLs; no frame may hold it (``frame-ancestors 'none'``,
  ``X-Frame-Options: DENY``);
- a session's files (its report.html): ``Content-Security-Policy: sandbox allow-scripts``, so a report
  received from someone else runs in an origin of its own, never the app's, and ``frame-ancestors 'self'``:
  only the app may frame it;
- everything else (the API): ``default-src 'none'`` and not frameable.
"""

from __future__ import annotations

import base64
import hashlib
import re
from pathlib import Path

__all__ = ["page_policy", "security_headers"]

_COMMON = [(b"x-content-type-options", b"nosniff"), (b"referrer-policy", b"no-referrer"),
           (b"cross-origin-resource-policy", b"same-origin")]
#: A session's files: the report's own viewer runs, in a sandbox of its own; only the app may frame it.
SESSION_FILE_POLICY = "sandbox allow-scripts; frame-ancestors 'self'"
_API_POLICY = "default-src 'none'; frame-ancestors 'none'"


def _inline_script_hashes(html: str) -> list[str]:
    return ["'sha256-" + base64.b64encode(hashlib.sha256(body.encode()).digest()).decode() + "'"
            for body in re.findall(r"<script[^>]*>(.*?)</script>", html, flags=re.S) if body.strip()]


def page_policy(index_html: Path) -> str:
    """The app page's CSP (``{host}`` to fill in with the Host it was asked by): its inline scripts (the import
    map) allowed by their hashes, nothing else inline."""
    hashes = " ".join(_inline_script_hashes(index_html.read_text(encoding="utf-8")))
    return ("default-src 'none'; script-src 'self' " + hashes + "; style-src 'self'; img-src 'self' blob: data:; "
            "connect-src 'self' ws://{host}; frame-src 'self'; base-uri 'none'; form-action 'none'; "
            "frame-ancestors 'none'")


def security_headers(path: str, host: str, page_csp: str) -> list[tuple[bytes, bytes]]:
    """The headers added to the response to ``path`` asked with Host ``host`` (already checked by the gate)."""
    if path == "/":
        policy, frames = page_csp.format(host=host), b"DENY"
    elif path.startswith("/api/sessions/") and "/files/" in path:
        policy, frames = SESSION_FILE_POLICY, b"SAMEORIGIN"
    elif path.startswith("/static/"):
        policy, frames = None, b"DENY"
    else:
        policy, frames = _API_POLICY, b"DENY"
    out = [*_COMMON, (b"x-frame-options", frames)]
    if policy:
        out.append((b"content-security-policy", policy.encode("latin-1")))
    return out
