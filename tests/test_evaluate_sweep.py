"""``ptw-assist evaluate``'s sweep form (issue 22): one row per episode, the same numbers as one
``evaluate`` episode, serially, in local processes and on a Dask LocalCluster; resume; bad sweeps refused."""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import pytest

from assist.cli import main
from assist.evaluate import SWEEP_COLUMNS, run_episode
from test_jobs import needs_dask

ARGS = ["--controllers", "ts,lqr", "--speeds", "40,80", "--seeds", "2", "--no-progress"]


def _run(args: list[str]) -> int:
    try:
        return main(["evaluate", *[a for a in args if a != "--no-progress"]])
    except SystemExit as e:  # argparse's usage errors
        return int(e.code)


def _rows(path: Path) -> list[dict]:
    return json.loads(path.read_text())["rows"]


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    assert _run([*ARGS, "--table", str(d / "t.csv"), "--json", str(d / "s.json"), "--plot", str(d / "s.png")]) == 0
    return d


def test_a_sweep_row_is_the_episode_evaluate_runs(serial):
    rows = _rows(serial / "s.json")
    assert len(rows) == 8 and [(r["controller"], r["speed_kmh"], r["seed"]) for r in rows][:3] == \
        [("ts", 40.0, 0), ("ts", 40.0, 1), ("ts", 80.0, 0)]
    for r in (rows[0], rows[-1]):
        m = run_episode(r["controller"], r["scenario"], speed_kmh=r["speed_kmh"], noise_pct=r["noise_pct"],
                        seed=r["seed"]).metrics()
        assert m["roll_rmse_deg"] == r["roll_rmse_deg"] and m["torque_max_nm"] == r["torque_max_nm"]
    with open(serial / "t.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert tuple(table[0]) == SWEEP_COLUMNS and len(table) == 8
    assert float(table[0]["roll_rmse_deg"]) == rows[0]["roll_rmse_deg"]  # repr round trip: exact
    summ = json.loads((serial / "s.json").read_text())["summary"]
    assert {(s["controller"], s["speed_kmh"]) for s in summ} == {("ts", 40.0), ("ts", 80.0), ("lqr", 40.0), ("lqr", 80.0)}
    assert (serial / "s.png").stat().st_size > 10_000


def test_local_processes_give_the_serial_rows(serial, tmp_path):
    assert _run([*ARGS, "--table", str(tmp_path / "t.csv"), "--json", str(tmp_path / "s.json"), "--workers", "2"]) == 0
    assert _rows(tmp_path / "s.json") == _rows(serial / "s.json")


@needs_dask
def test_a_dask_local_cluster_gives_the_serial_rows(serial, tmp_path, monkeypatch):
    here = str(Path(__file__).resolve().parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([here, os.environ.get("PYTHONPATH", "")]))
    assert _run([*ARGS, "--table", str(tmp_path / "t.csv"), "--json", str(tmp_path / "s.json"), "--workers", "2",
                 "--scheduler", "local"]) == 0
    assert _rows(tmp_path / "s.json") == _rows(serial / "s.json")


def test_a_sweep_file_and_resume(tmp_path):
    sw = tmp_path / "sweep.json"
    sw.write_text(json.dumps({"controllers": ["lqr"], "scenarios": ["double_lane_change"], "speeds_kmh": [50],
                              "seeds": [0, 1], "effects": [[], ["road_bank:bank_rad=0.03"]], "noise_pct": 2}))
    t = tmp_path / "t.csv"
    assert _run(["--sweep", str(sw), "--table", str(t)]) == 0
    jobs = Path(str(t) + ".jobs.jsonl")
    first = jobs.read_text().splitlines()
    assert len(first) == 4
    sw.write_text(json.dumps({"controllers": ["lqr"], "scenarios": ["double_lane_change"], "speeds_kmh": [50],
                              "seeds": [0, 1, 2], "effects": [[], ["road_bank:bank_rad=0.03"]], "noise_pct": 2}))
    assert _run(["--sweep", str(sw), "--table", str(t)]) == 2  # a previous run: refused without --resume
    assert _run(["--sweep", str(sw), "--table", str(t), "--resume"]) == 0
    lines = jobs.read_text().splitlines()
    assert lines[:4] == first and len(lines) == 6  # only the two new episodes ran
    with open(t, newline="") as f:
        table = list(csv.DictReader(f))
    assert [r["effects"] for r in table].count("road_bank:bank_rad=0.03") == 3 and {r["noise_pct"] for r in table} == {"2.0"}
    # the file's numbers are read as the command line reads them (--noise 2 is 2.0 too)


def test_bad_sweeps_are_refused(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"controllers": ["ts"], "speeds": [50]}))
    nan = tmp_path / "nan.json"
    nan.write_text('{"noise_pct": NaN}')
    files = {}
    for name, obj in (("effect", {"effects": [["nonsense:x=1"]]}), ("noise", {"noise_pct": 1000}),
                      ("seed", {"seeds": [2**64]}), ("speeds", {"speeds_kmh": [50, 50.0]})):
        files[name] = tmp_path / f"{name}.json"
        files[name].write_text(json.dumps(obj))
    cases = [
        (["--seeds", "2"], "--table"),
        (["--sweep", str(bad), "--table", str(tmp_path / "a.csv")], "unknown key(s) ['speeds']"),
        (["--sweep", str(nan), "--table", str(tmp_path / "b.csv")], "NaN"),
        (["--scenarios", "nowhere", "--table", str(tmp_path / "c.csv")], "'nowhere'"),
        (["--controllers", "pid", "--table", str(tmp_path / "d.csv")], "pid"),
        (["--speeds", "40,-3", "--table", str(tmp_path / "e.csv")], "--speeds"),
        (["--table", str(tmp_path / "f.csv")], "sweep form"),
        (["--seeds", "2", "--table", str(tmp_path / "g.csv"), "--resume"], "--resume"),
        (["--speeds", "50,50", "--table", str(tmp_path / "h.csv")], "50.0 given twice"),
        (["--scenarios", "urban", "--speeds", "50", "--table", str(tmp_path / "i.csv")], "no cruise speed"),
        (["--seeds", "2", "--table", str(tmp_path / "j.csv"), "--json", str(tmp_path / "j.csv")], "--table"),
        (["--sweep", str(files["effect"]), "--table", str(tmp_path / "k.csv")], "nonsense"),
        (["--sweep", str(files["noise"]), "--table", str(tmp_path / "l.csv")], "1000"),
        (["--sweep", str(files["seed"]), "--table", str(tmp_path / "m.csv")], str(2**64)),
        (["--sweep", str(files["speeds"]), "--table", str(tmp_path / "n.csv")], "50.0 given twice"),
    ]
    for args, msg in cases:
        assert _run(args) == 2, args
        err = capsys.readouterr().err
        assert msg in err and "Traceback" not in err, (args, err)
