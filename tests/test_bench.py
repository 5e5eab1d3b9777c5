"""Smoke test of ``asnn bench`` (output shape only; no timing assertions)."""

import json

from cli.main import main


def test_bench_json_report_shape(capsys):
    assert main(["bench", "--frames", "3", "--size", "64x64", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert "setNumThreads(1)" in report["threads"] and report["machine"]["cores"] >= 1
    rows = report["results"]
    assert {r["model"] for r in rows} == {"asnn", "lgmd1", "lgmd2"}
    for r in rows:
        assert r["size"] == "64x64" and r["frames"] == 3
        assert 0 < r["median_ms"] <= r["p90_ms"]
    slow = [r for r in rows if r["form"] == "straightforward"]
    assert len(slow) == 1 and slow[0]["preset"] == report["default_preset"]
    assert slow[0]["speedup"] > 0
    assert all(r["state_mb"] > 0 for r in rows if r["model"] == "asnn")
