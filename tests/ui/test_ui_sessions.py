"""The Sessions page's data (issue 37): the sessions under --sessions with their state and figures, their files
opened through the app, nothing outside the folder."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from support.ui_server import start_ui


@pytest.fixture(scope="module")
def server(reference_session, tmp_path_factory):
    sessions = tmp_path_factory.mktemp("sessions")
    shutil.copytree(reference_session, sessions / "done")
    shutil.copytree(reference_session, sessions / "taken")
    subprocess.run([sys.executable, "-m", "rangekit", "-q", "process", str(sessions / "done"), "--no-report"],
                   check=True, stdin=subprocess.DEVNULL, capture_output=True, timeout=600)
    outside = tmp_path_factory.mktemp("outside")
    shutil.copytree(reference_session, outside / "elsewhere")
    (sessions / "linked").symlink_to(outside / "elsewhere")
    (sessions / "broken").mkdir()
    (sessions / "broken" / "session.json").write_text("{not json")
    s = start_ui(sessions)
    s.sessions = sessions
    yield s
    s.stop()


def test_the_sessions_are_listed_with_their_state_and_figures(server):
    rows = {r["name"]: r for r in json.loads(server.request("/api/sessions")[1])["sessions"]}
    assert set(rows) == {"done", "taken", "broken"}         # the link out of the folder is not listed
    assert rows["taken"]["state"] == "acquired" and rows["taken"]["files"] == []
    done = rows["done"]
    summary = json.loads((server.sessions / "done" / "summary.json").read_text())
    assert done["state"] == "processed" and done["views_done"] == done["views"] == len(summary["views"])
    assert done["vertices"] == summary["mesh"]["vertices"] and "mesh.ply" in done["files"]
    assert rows["broken"]["state"] == "unreadable" and "session.json" in rows["broken"]["error"]


def test_a_sessions_files_open_and_nothing_else(server):
    status, body, headers = server.request("/api/sessions/done/files/mesh.ply")
    assert status == 200 and body == (server.sessions / "done" / "mesh.ply").read_bytes()
    for path, words in [("/api/sessions/done/files/session.json", "not one a page may open"),
                        ("/api/sessions/linked/files/mesh.ply", "a link out of the sessions folder"),
                        ("/api/sessions/done/files/preview.ply", "not there (yet)")]:
        status, body, _ = server.request(path)
        assert status == 404 and words in json.loads(body)["error"], body
