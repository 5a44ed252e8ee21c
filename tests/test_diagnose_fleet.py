"""``ptw-assist diagnose`` on many logs (cli.md, issue 22): one report per log and a fleet table, the same
verdicts serially, in local processes and on a Dask LocalCluster; a rerun resumes; bad fleets refused."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from assist.cli import main
from ptw_env.logs import write_log
from test_diagnose import ride
from test_jobs import needs_dask

CASES = {"bank": {"road_bank": {"bank_rad": 0.05}}, "payload": {"payload": {"mass_kg": 60.0}}, "clean": None}


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet_logs")
    for i, (name, eff) in enumerate(CASES.items()):
        write_log(d / f"{name}.csv", ride("double_lane_change", eff, seed=20 + i, duration_s=24.0))
    return d


def _run(args: list[str]) -> int:
    try:
        return main(["diagnose", *args, "--pairs", "none", "--no-progress"])
    except SystemExit as e:  # argparse's usage errors (a bad option value) exit with 2
        return int(e.code)


@pytest.fixture(scope="module")
def serial(logs, tmp_path_factory):
    out = tmp_path_factory.mktemp("fleet_serial")
    assert _run([str(logs), "--out", str(out / "r"), "--json", str(out / "fleet.json"), "--plot",
                 str(out / "fleet.png")]) == 0
    return out


def test_one_report_per_log_and_a_fleet_table(serial, logs):
    fleet = json.loads((serial / "fleet.json").read_text())
    rows = {r["log_name"]: r for r in fleet["logs"]}
    assert list(rows) == ["bank", "clean", "payload"]  # a folder's logs, sorted
    assert rows["bank"]["causes"][0]["cause"] == "road_bank"
    assert rows["bank"]["causes"][0]["params"]["bank_rad"] == pytest.approx(0.05, rel=0.25)
    assert rows["payload"]["causes"][0]["cause"] == "payload"
    assert rows["clean"]["causes"] == [{"cause": "none", "params": {}}]
    assert fleet["vehicles"]["reference-scooter"]["model_sha256"]
    for name, r in rows.items():  # the per-log report is diagnose.md's, as for one log
        rep = json.loads((serial / "r" / f"{name}.json").read_text())
        assert rep["verdict"]["causes"] == r["causes"] and rep["log"] == str(logs / f"{name}.csv")
        assert (serial / "r" / f"{name}.png").stat().st_size > 10_000
    table = (serial / "r" / "fleet.csv").read_text().splitlines()
    assert table[0].startswith("log,vehicle,causes,gain") and len(table) == 4
    assert (serial / "fleet.png").stat().st_size > 10_000


def _rows(path: Path) -> list[dict]:
    return json.loads(path.read_text())["logs"]


def test_local_processes_give_the_serial_verdicts(serial, logs, tmp_path):
    assert _run([str(logs / "*.csv"), "--out", str(tmp_path / "r"), "--workers", "2", "--json",
                 str(tmp_path / "f.json")]) == 0
    assert _rows(tmp_path / "f.json") == _rows(serial / "fleet.json")


@needs_dask
def test_a_dask_local_cluster_gives_the_serial_verdicts(serial, logs, tmp_path, monkeypatch):
    here = str(Path(__file__).resolve().parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([here, os.environ.get("PYTHONPATH", "")]))
    assert _run([str(logs), "--out", str(tmp_path / "r"), "--scheduler", "local", "--workers", "2", "--json",
                 str(tmp_path / "f.json")]) == 0
    assert _rows(tmp_path / "f.json") == _rows(serial / "fleet.json")


def test_a_rerun_resumes_and_diagnoses_only_the_new_log(logs, tmp_path, capsys):
    out = tmp_path / "r"
    assert _run([str(logs / "bank.csv"), str(logs / "clean.csv"), "--out", str(out)]) == 0
    stamp = (out / "bank.json").stat().st_mtime_ns
    assert _run([str(logs), "--out", str(out)]) == 2  # not empty: refused without --resume
    assert "--resume" in capsys.readouterr().err
    assert _run([str(logs), "--out", str(out), "--resume"]) == 0
    assert (out / "bank.json").stat().st_mtime_ns == stamp  # done before: not run again
    assert len((out / "fleet_jobs.jsonl").read_text().splitlines()) == 3
    assert (out / "payload.json").exists()


def test_a_log_too_short_to_diagnose_stops_the_fleet_before_any_work(logs, tmp_path, capsys):
    d = tmp_path / "logs"
    d.mkdir()
    for name in ("bank", "clean"):
        for suffix in (".csv", ".json"):
            (d / f"{name}{suffix}").write_bytes((logs / f"{name}{suffix}").read_bytes())
    text = (logs / "clean.csv").read_text().splitlines()
    (d / "short.csv").write_text("\n".join(text[:200]) + "\n")  # 2 s of the clean ride
    assert _run([str(d), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "short.csv" in err and "replay window" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()  # refused before any diagnosis: nothing written


def test_bad_fleets_are_refused(logs, tmp_path, capsys):
    other = tmp_path / "other"
    other.mkdir()
    (other / "bank.csv").write_bytes((logs / "bank.csv").read_bytes())
    (other / "bank.json").write_bytes((logs / "bank.json").read_bytes())
    cases = [
        ([str(logs)], "--out DIR"),  # many logs, nowhere to put the reports
        ([str(logs / "bank.csv"), str(other / "bank.csv"), "--out", str(tmp_path / "x")], "two logs named 'bank'"),
        ([str(tmp_path / "*.nothing"), "--out", str(tmp_path / "y")], "no file matches"),
        ([str(logs / "bank.csv"), "--resume"], "for many logs"),
        ([str(logs), "--out", str(logs), "--overwrite"], "sidecar"),
        ([str(logs), "--out", str(tmp_path / "z"), "--workers", "0"], "--workers"),
        ([str(logs), "--out", str(tmp_path / "w"), "--scheduler", "8786"], "--scheduler"),
    ]
    for args, msg in cases:
        assert _run(args) == 2, args
        err = capsys.readouterr().err
        assert msg in err and "Traceback" not in err, (args, err)
