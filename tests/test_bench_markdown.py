"""The markdown blocks that make docs-figures writes into docs/benchmarks.md are well-formed tables: every
row has the header's number of cells, and the sentences state the targets (pure formatting, no timing)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[1]


def _bench(path: str):
    """The benchmark script benchmarks/PATH.py (e.g. ``app/bench_process``), loaded as a module."""
    spec = importlib.util.spec_from_file_location(Path(path).name, ROOT / "benchmarks" / f"{path}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _cells(line: str) -> int:
    return line.count("|") - 1


def _table_is_rectangular(text: str) -> list[str]:
    rows = [line for line in text.splitlines() if line.startswith("|")]
    assert len(rows) >= 3 and set(rows[1]) <= {"|", "-"}
    assert {_cells(r) for r in rows} == {_cells(rows[0])}, rows
    return rows


def test_process_block():
    bench = _bench("app/bench_process")
    summary = {"seconds": {"decode": 7.0, "register": 3.2, "fuse": 19.4, "evaluate": 8.0, "report": 3.7},
               "accuracy": {"rms": 1.69e-5, "p95": 1.91e-5, "completeness": 0.996, "watertight": {"rms": 1.55e-4}}}
    text = bench.markdown({"wall_s": 37.0, "cpu_s": 39.0, "peak_gb": 1.9}, summary)
    rows = _table_is_rectangular(text)
    assert rows[0].split("|")[5:-1] == [f" {k} " for k in summary["seconds"]]
    assert "Targets met in this run: CPU." in text
    assert "observed mesh 0.0169 mm RMS, 95th percentile 0.0191 mm, completeness 99.6%; closed mesh 0.155 mm" in text


def test_decode_stage_block():
    bench = _bench("coded/bench_decode_stage")
    best = {"png": 4.6, "decode": 2.3, "triangulate": 1.2, "filter+normals": 0.5, "sigma": 0.3, "write": 0.5,
            "other": 0.9, "wall": 10.4}
    text = bench.markdown(best, 10.3, 2021957, SimpleNamespace(serial=True, views=12, repeat=1))
    rows = _table_is_rectangular(text)
    assert len(rows) == 2 + 7 + 2 and "| **stage, CPU s** | **10.30** |" in rows
    assert text.endswith("2,021,957 points. Target 8 CPU-s: not met in this run.")
