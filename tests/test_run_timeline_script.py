"""scripts/run_timeline.py: job intervals, idle gaps and utilisation from hand-made job rows."""

from __future__ import annotations

import json

import pytest


def _row(job: str, worker: str, start: str, wall: float, method: str = "monosdf", table: str = "ablation",
         status: str = "ok") -> dict:
    """A stored result row (the fields ``collect_results`` requires); oracle_tsdf jobs have no schedule."""
    return {"job_id": job, "table": table, "row": "r", "method": method, "scene": "s", "dataset": "scannet", "seed": 0,
            "scale": "small", "worker_name": worker, "created": start, "wall_seconds": wall, "status": status,
            "config": {"iterations": 0 if method == "oracle_tsdf" else 2000}}


def _write(root, rows: list[dict]) -> None:
    folder = root / "small" / "jobs"
    folder.mkdir(parents=True)
    for r in rows:
        (folder / f"{r['job_id']}.json").write_text(json.dumps(r))


def _rows() -> list[dict]:
    # worker a: [0, 100], [100, 160]; worker b: [0, 40], idle 40-90, [90, 150], idle to the end (160)
    return [_row("j1", "a", "2026-01-01T00:00:00+00:00", 100.0),
            _row("j2", "a", "2026-01-01T00:01:40+00:00", 60.0, method="oracle_tsdf"),
            _row("j3", "b", "2026-01-01T00:00:00+00:00", 40.0, table="dense"),
            _row("j4", "b", "2026-01-01T00:02:30+00:00", 60.0, status="failed"),  # a failed row is stamped at its end
            {**_row("j5", "b", "2026-01-01T00:00:00+00:00", 0.0), "wall_seconds": None}]  # never ran: skipped


def test_intervals_gaps_and_utilisation(load_script, tmp_path):
    from bench.results_io import collect_results

    rt = load_script("run_timeline")
    _write(tmp_path, _rows())
    (tmp_path / "small" / "jobs" / ".tmp-j6.json").write_text("{half-written")  # the atomic writer's temporary: skipped
    df = rt.job_intervals(collect_results(tmp_path / "small"))
    assert list(df["job_id"]) == ["j1", "j3", "j4", "j2"]
    j4 = df[df["job_id"] == "j4"].iloc[0]
    assert (j4["start"], j4["end"]) == (90.0, 150.0)
    gaps = rt.idle_gaps(df)
    assert [(g.worker, g.start, g.end) for g in gaps.itertuples()] == [("b", 40.0, 90.0), ("b", 150.0, 160.0)]
    s = rt.summary(df)
    assert s["span"] == 160.0 and s["workers"] == 2 and s["job_seconds"] == 260.0
    assert s["utilisation"] == pytest.approx(260.0 / 320.0)
    assert s["by_kind"].loc["oracle_tsdf (fusion only)", "jobs"] == 1
    assert s["by_kind"].loc["monosdf", "job_seconds"] == 200.0
    assert s["by_table"].loc["dense", "jobs"] == 1 and s["by_table"].loc["ablation", "jobs"] == 3


def test_the_script_prints_the_summary_and_draws_the_chart(load_script, tmp_path, monkeypatch, capsys):
    _write(tmp_path, _rows())
    png = tmp_path / "t.png"
    monkeypatch.setattr("sys.argv", ["run_timeline", str(tmp_path), "--png", str(png)])
    load_script("run_timeline").main()
    out = capsys.readouterr().out
    assert "4 jobs on 2 workers: span 2.7 min" in out and "utilisation 81.2 %" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_an_empty_folder_is_one_clear_error(load_script, tmp_path, monkeypatch):
    monkeypatch.setattr("sys.argv", ["run_timeline", str(tmp_path)])
    with pytest.raises(SystemExit, match="no job rows in"):
        load_script("run_timeline").main()
