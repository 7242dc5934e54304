"""Batch on Ray: failure isolation and skip-on-rerun, with a trivial job."""

import json
from pathlib import Path

from kinemaforge_opt.batch import run_batch, summary_table


def _double(input_dir, out_dir):
    x = float((Path(input_dir) / "x.txt").read_text())
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    (Path(out_dir) / "y.txt").write_text(str(2 * x))
    return {"y": 2 * x}


def test_corrupt_input_is_reported_and_others_finish_then_skipped(tmp_path):
    inputs = []
    for name, text in (("a", "1"), ("bad", "not a number"), ("c", "3")):
        d = tmp_path / "in" / name
        d.mkdir(parents=True)
        (d / "x.txt").write_text(text)
        inputs.append(d)
    out = tmp_path / "out"
    items = run_batch(inputs, out, _double, workers=2, progress=False)
    status = {it.name: it.status for it in items}
    assert status == {"a": "ok", "bad": "error", "c": "ok"}
    assert "ValueError" in items[1].error
    assert json.loads((out / "bad" / "status.json").read_text())["status"] == "error"
    assert (out / "c" / "y.txt").read_text() == "6.0"
    table = summary_table(items)
    assert "2 done" in table and "1 failed" in table

    (tmp_path / "in" / "bad" / "x.txt").write_text("5")  # fixed: re-run retries it, skips the rest
    again = run_batch(inputs, out, _double, workers=2, progress=False)
    assert [it.status for it in again] == ["skipped", "ok", "skipped"]
    assert again[0].result == {"y": 2.0}


def test_job_inputs_that_are_not_what_the_job_reads_are_named(tmp_path):
    import pytest

    from kinemaforge_opt.batch.jobs import JOBS
    from kinemaforge_opt.errors import InputFileError

    (tmp_path / "empty").mkdir()
    with pytest.raises(InputFileError, match="empty.*no sequence.json"):
        JOBS["reconstruct"](tmp_path / "empty", tmp_path / "out")
    with pytest.raises(InputFileError, match="empty.*has no model.urdf"):
        JOBS["diagnose"](tmp_path / "empty", tmp_path / "out")


def _thread_env(input_dir, out_dir):
    import os

    return {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}


def test_local_workers_run_single_threaded_blas_and_the_driver_env_is_restored(tmp_path, monkeypatch):
    import os

    monkeypatch.setenv("OMP_NUM_THREADS", "7")
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    (tmp_path / "in").mkdir()
    items = run_batch([tmp_path / "in"], tmp_path / "out", _thread_env, workers=1, progress=False)
    assert items[0].result == {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    assert os.environ["OMP_NUM_THREADS"] == "7" and "OPENBLAS_NUM_THREADS" not in os.environ
    doc = json.loads((tmp_path / "out" / "in" / "status.json").read_text())
    assert doc["started_unix_s"] <= doc["finished_unix_s"]
