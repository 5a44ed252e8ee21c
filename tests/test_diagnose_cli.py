"""``ptw-assist diagnose`` (diagnose.md): report and figure written, bad logs get one clear line and exit 2."""

from __future__ import annotations

import json

import pytest

from assist.cli import main
from ptw_env.logs import write_log
from test_diagnose import ride


@pytest.fixture(scope="module")
def log_path(tmp_path_factory):
    p = tmp_path_factory.mktemp("diag") / "ride.csv"
    write_log(p, ride("double_lane_change", {"ay_frame": {"gravity_gain": 0.6}}, seed=8, duration_s=24.0))
    return p


def test_cli_writes_the_report_and_the_plot(log_path, tmp_path, capsys):
    out, png = tmp_path / "report.json", tmp_path / "report.png"
    rc = main(["diagnose", str(log_path), "--json", str(out), "--plot", str(png), "--pairs", "none", "--no-progress"])
    assert rc == 0
    j = json.loads(out.read_text())
    assert j["log"] == str(log_path)
    assert j["verdict"]["causes"][0]["cause"] == "ay_frame"
    assert j["verdict"]["causes"][0]["params"]["gravity_gain"] == pytest.approx(0.6, rel=0.25)
    assert png.stat().st_size > 10_000
    text = capsys.readouterr().out
    assert "verdict: ay_frame" in text and "report written" in text
    # an existing output is not overwritten without --overwrite
    rc = main(["diagnose", str(log_path), "--json", str(out), "--pairs", "none", "--no-progress"])
    assert rc == 2
    assert "exists" in capsys.readouterr().err


def test_cli_bad_log_names_file_line_and_column(tmp_path, capsys):
    p = tmp_path / "bad.csv"
    p.write_text("t,tau,vx,delta,delta_rate,yaw_rate,roll_rate,ay\n0,0,10,0,0,0,0,0\n0.01,0,10,0,x,0,0,0\n")
    rc = main(["diagnose", str(p), "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("ptw-assist diagnose: error:")
    assert str(p) in err[0] and "line 3" in err[0] and "delta_rate" in err[0]


def test_cli_missing_file_and_short_log(tmp_path, capsys):
    assert main(["diagnose", str(tmp_path / "nope.csv"), "--no-progress"]) == 2
    assert "no such file" in capsys.readouterr().err
    p = tmp_path / "short.csv"
    write_log(p, ride("double_lane_change", None, seed=1, duration_s=20.0).columns | {}, meta={})
    lines = p.read_text().splitlines()[:300]  # 3 s: fewer than 8 windows of 0.5 s
    p.write_text("\n".join(lines) + "\n")
    assert main(["diagnose", str(p), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "usable replay window" in err and str(p) in err


def test_cli_rejects_unknown_option(log_path):
    with pytest.raises(SystemExit) as exc:
        main(["diagnose", str(log_path), "--windw", "2"])
    assert exc.value.code == 2
