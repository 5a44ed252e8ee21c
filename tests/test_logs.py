"""Ride-log reader and writer (ptw_env.logs) against logs.md and the reference data."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from ptw_env.logs import (
    MIN_SAMPLES,
    PHYSICAL_BOUNDS,
    REQUIRED_COLUMNS,
    LogDataError,
    LogFormatError,
    RideLog,
    read_log,
    write_log,
)

from conftest import DATA  # noqa: E402  (shared/data beside the repository)
HEADER = "t,tau,vx,delta,delta_rate,yaw_rate,roll_rate,ay"


def rows(n: int = 200, dt: float = 0.01) -> list[list[str]]:
    """n good data rows as text cells in HEADER order."""
    out = []
    for k in range(n):
        t = k * dt
        out.append([f"{t:.2f}", f"{math.sin(t):.5f}", "15.0", "0.001", "0.01", "0.02", "0.03", f"{0.5 * t:.4f}"])
    return out


def text(cells: list[list[str]], header: str = HEADER) -> str:
    return header + "\n" + "".join(",".join(r) + "\n" for r in cells)


def write(tmp_path: Path, content: str | bytes, name: str = "ride.csv") -> Path:
    p = tmp_path / name
    if isinstance(content, bytes):
        p.write_bytes(content)
    else:
        p.write_text(content, encoding="utf-8")
    return p


def columns(n: int = 300, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    cols = {c: rng.standard_normal(n) * 10.0 ** rng.integers(-6, 1) for c in REQUIRED_COLUMNS}
    for c in REQUIRED_COLUMNS:  # any digits, within what a sensor can read (PHYSICAL_BOUNDS)
        cols[c] = np.clip(cols[c], *PHYSICAL_BOUNDS[c])
    cols["t"] = 3.0 + np.arange(n) * 0.01
    return cols


# --------------------------------------------------------------------------- round trip


def test_round_trip_is_exact(tmp_path):
    cols = columns()
    cols["roll"] = np.random.default_rng(1).standard_normal(300) * 1e-3
    cols["x_Fyf"] = np.random.default_rng(2).standard_normal(300) * 1e3  # an extra column
    cols["delta"][[5, 17, 299]] = np.nan  # dropouts
    cols["ay"][0] = 1e-300
    cols["x_Fyf"][1] = -7.123456789012345e12  # digits of an extra column are kept whatever their size
    meta = {
        "vehicle": "reference-scooter",
        "sample_rate_hz": 100,
        "truth": {"causes": [{"cause": "none", "params": {}}]},
    }
    path = write_log(tmp_path / "ride.csv", cols, meta=meta)
    log = read_log(path)
    assert list(log.columns) == list(REQUIRED_COLUMNS) + ["roll", "x_Fyf"]
    for c, v in cols.items():
        np.testing.assert_array_equal(log[c], v)  # repr round-trips the double exactly
    assert log.meta == meta
    assert log.path == path
    # and again through a RideLog, which carries its own meta
    again = read_log(write_log(tmp_path / "again.csv", log))
    for c in cols:
        np.testing.assert_array_equal(again[c], log[c])
    assert again.meta == meta


def test_columns_are_written_in_logs_md_order(tmp_path):
    cols = columns(20)
    shuffled = {"extra": np.ones(20), "roll": np.zeros(20)} | {c: cols[c] for c in reversed(REQUIRED_COLUMNS)}
    path = write_log(tmp_path / "ride.csv", shuffled)
    header = path.read_text().splitlines()[0].split(",")
    assert header == list(REQUIRED_COLUMNS) + ["roll", "extra"]
    assert not (tmp_path / "ride.json").exists()


@pytest.mark.parametrize("csv_path", sorted(DATA.glob("*.csv")), ids=lambda p: p.name)
def test_reads_every_reference_log(csv_path):
    log = read_log(csv_path)
    sidecar = json.loads(csv_path.with_suffix(".json").read_text())
    assert log.meta == sidecar
    assert log.sample_rate_hz == pytest.approx(sidecar["sample_rate_hz"], rel=1e-9)
    assert len(log) == round(sidecar["duration_s"] * sidecar["sample_rate_hz"])
    assert log.duration_s == pytest.approx(sidecar["duration_s"], rel=1e-9)
    for c in REQUIRED_COLUMNS + ("roll",):
        assert log.has(c) and np.all(np.isfinite(log[c]))
    # values against an independent parser
    with open(csv_path, newline="") as f:
        table = list(csv.reader(f))
    np.testing.assert_array_equal(log.to_array(table[0]), np.array(table[1:], dtype=float))
    assert log.t[0] == 0.0 and log.dt == pytest.approx(0.01, rel=1e-9)


def test_reference_noiseless_twin_has_the_true_states():
    log = read_log(DATA / "nominal_urban_noiseless.csv")
    assert [c for c in log.columns if c.startswith("x_")] == [
        "x_phi", "x_delta", "x_vy", "x_r", "x_phi_dot", "x_delta_dot", "x_Fyf", "x_Fyr",
    ]  # fmt: skip
    np.testing.assert_allclose(log["x_phi"], log.roll, rtol=0, atol=2e-12)  # printed to 10 digits each
    np.testing.assert_allclose(log.ay, (log["x_Fyf"] + log["x_Fyr"]) / 303.31, rtol=1e-8, atol=1e-10)


def test_ridelog_accessors():
    cols = columns(50)
    log = RideLog(t=cols["t"], columns={c: v for c, v in cols.items() if c != "t"})
    assert list(log.columns)[0] == "t" and len(log) == 50
    assert log.dt == pytest.approx(0.01) and log.sample_rate_hz == pytest.approx(100.0)
    assert log.duration_s == pytest.approx(0.5)
    assert log.roll is None and not log.has("roll") and log.has("ay")
    np.testing.assert_array_equal(log.yaw_rate, cols["yaw_rate"])
    arr = log.to_array(["ay", "t"])
    assert arr.shape == (50, 2)
    np.testing.assert_array_equal(arr[:, 1], cols["t"])
    with pytest.raises(LogDataError, match="no column 'roll'"):
        log["roll"]


# --------------------------------------------------------------------------- accepted variants


def test_dropouts_read_as_nan(tmp_path):
    cells = rows()
    cells[10][7] = ""  # ay empty
    cells[11][3] = "  "  # delta blank
    cells[12][5] = ""  # yaw_rate empty
    log = read_log(write(tmp_path, text(cells)))
    assert np.isnan(log.ay[10]) and np.isnan(log.delta[11]) and np.isnan(log.yaw_rate[12])
    assert np.sum(np.isnan(log.to_array(REQUIRED_COLUMNS))) == 3
    assert log.ay[9] == pytest.approx(0.5 * 0.09)


def test_free_order_extras_crlf_bom_spaces_and_trailing_blank_lines(tmp_path):
    cells = rows()
    order = [7, 0, 2, 1, 3, 4, 5, 6]
    names = HEADER.split(",")
    header = " , ".join(names[i] for i in order) + ",speed_wheel"
    body = "".join(",".join(r[i] for i in order) + ",1.5\r\n" for r in cells)
    p = write(tmp_path, ("\ufeff" + header + "\r\n" + body + "\r\n\r\n").encode("utf-8"))
    log = read_log(p)
    assert list(log.columns) == [names[i] for i in order] + ["speed_wheel"]
    assert len(log) == 200 and np.all(log["speed_wheel"] == 1.5)
    np.testing.assert_array_equal(log.t, np.array([r[0] for r in cells], dtype=float))


def test_jitter_within_tolerance_is_accepted(tmp_path):
    cells = rows()
    cells[50][0] = "0.50004"  # 0.4 % of a step
    assert len(read_log(write(tmp_path, text(cells)))) == 200


def test_no_sidecar_is_valid_and_min_duration_is_a_parameter(tmp_path):
    p = write(tmp_path, text(rows(MIN_SAMPLES)))
    with pytest.raises(LogFormatError, match="too short"):
        read_log(p)
    log = read_log(p, min_duration_s=0.0)
    assert log.meta == {} and len(log) == MIN_SAMPLES


# --------------------------------------------------------------------------- bad logs


def bad(tmp_path, content, **kw) -> LogFormatError:
    p = write(tmp_path, content)
    with pytest.raises(LogFormatError) as info:
        read_log(p, **kw)
    err = info.value
    assert err.path == p
    assert str(err).startswith(str(p))
    assert "\n" not in str(err)
    return err


def test_text_in_number_field_message(tmp_path):
    cells = rows()
    cells[55][7] = "abc"  # data row 56 = line 57
    err = bad(tmp_path, text(cells))
    assert (err.line, err.column) == (57, "ay")
    assert str(err).endswith("ride.csv, line 57, column 'ay': 'abc' is not a number (plain ASCII decimal expected)")


def test_empty_file(tmp_path):
    for content in ("", "\n  \n"):
        err = bad(tmp_path, content)
        assert err.line == 1 and "empty" in str(err)


def test_missing_required_column(tmp_path):
    cells = [r[:7] for r in rows()]
    err = bad(tmp_path, text(cells, header=HEADER.replace(",ay", "")))
    assert (err.line, err.column) == (1, "ay")
    assert "missing required column(s) ay" in str(err)
    assert "t, tau, vx, delta, delta_rate, yaw_rate, roll_rate" in str(err)  # what was found


def test_duplicate_column_names(tmp_path):
    cells = [r + ["0"] for r in rows()]
    err = bad(tmp_path, text(cells, header=HEADER + ",yaw_rate"))
    assert (err.line, err.column) == (1, "yaw_rate")
    assert "duplicate" in str(err) and "6 and 9" in str(err)


def test_empty_header_name(tmp_path):
    err = bad(tmp_path, text([r + ["0"] for r in rows()], header=HEADER + ", "))
    assert (err.line, err.column) == (1, 9)


@pytest.mark.parametrize("cut, column", [(5, "yaw_rate"), (9, None)])
def test_wrong_number_of_fields(tmp_path, cut, column):
    cells = rows()
    cells[30] = cells[30][:cut] if cut < 8 else cells[30] + ["1.0"]
    err = bad(tmp_path, text(cells))
    assert (err.line, err.column) == (32, column)
    assert f"{cut} fields, the header has 8" in str(err)


@pytest.mark.parametrize("cell", ["", " "])
def test_missing_time(tmp_path, cell):
    cells = rows()
    cells[20][0] = cell
    err = bad(tmp_path, text(cells))
    assert (err.line, err.column) == (22, "t")
    assert "time cannot be missing" in str(err)


@pytest.mark.parametrize("value", ["0.39", "0.40"])
def test_time_not_strictly_increasing_names_both_lines(tmp_path, value):
    cells = rows()
    cells[41][0] = value  # t[40] = 0.40 on line 42, this row is line 43
    err = bad(tmp_path, text(cells))
    assert (err.line, err.column) == (43, "t")
    assert "does not increase" in str(err) and "from t = 0.4 s on line 42" in str(err)


def test_missing_rows_are_non_uniform_sampling(tmp_path):
    cells = rows()
    del cells[100]  # t = 0.99 on line 101 is followed by 1.01 on line 102
    err = bad(tmp_path, text(cells))
    assert (err.line, err.column) == (102, "t")
    assert "non-uniform sampling" in str(err) and "t = 0.99 s on line 101" in str(err) and "0.02" in str(err)


def test_jitter_beyond_tolerance(tmp_path):
    cells = rows()
    cells[50][0] = "0.50003"
    cells[80][0] = "0.80015"  # 1.5 % of a step, line 82
    err = bad(tmp_path, text(cells))
    assert (err.line, err.column) == (82, "t")
    assert "on line 81" in str(err) and "0.0101" in str(err)


def test_too_short(tmp_path):
    err = bad(tmp_path, text(rows(MIN_SAMPLES - 1)), min_duration_s=0.0)
    assert err.column == "t" and "too short" in str(err) and f"{MIN_SAMPLES - 1} samples" in str(err)
    err = bad(tmp_path, text(rows(99)))  # 0.99 s < 1 s
    assert err.line == 100 and "0.99 s" in str(err)
    err = bad(tmp_path, HEADER + "\n")
    assert "0 samples" in str(err)


@pytest.mark.parametrize("cell", ["inf", "-inf", "Infinity", "1e999"])
def test_infinite_values_are_errors(tmp_path, cell):
    cells = rows()
    cells[7][4] = cell
    err = bad(tmp_path, text(cells))
    assert (err.line, err.column) == (9, "delta_rate")
    assert "not finite" in str(err)


def test_first_error_in_file_order(tmp_path):
    cells = rows()
    cells[3][6] = "x1"  # line 5
    cells[6] = cells[6][:3]  # line 8
    cells[2][2] = "inf"  # line 4, before both
    err = bad(tmp_path, text(cells))
    assert (err.line, err.column) == (4, "vx")


def test_blank_line_inside_data(tmp_path):
    content = text(rows()).splitlines(keepends=True)
    content.insert(60, "\n")  # becomes line 61
    err = bad(tmp_path, "".join(content))
    assert err.line == 61 and "blank line" in str(err)


def test_not_utf8(tmp_path):
    content = text(rows()).encode("utf-8").replace(b"15.0", b"15\xff0", 1)
    err = bad(tmp_path, content)
    assert err.line == 2 and "UTF-8" in str(err)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.csv"):
        read_log(tmp_path / "nope.csv")


def test_malformed_sidecar_names_file_and_line(tmp_path):
    p = write(tmp_path, text(rows()))
    side = tmp_path / "ride.json"
    side.write_text('{\n "vehicle": "reference-scooter",\n "sample_rate_hz": 100,\n}\n')
    with pytest.raises(LogFormatError) as info:
        read_log(p)
    err = info.value
    assert err.path == side and err.line == 4 and err.column == 1
    assert str(err).startswith(f"{side}, line 4, column 1: not valid JSON")


def test_sidecar_must_be_an_object_and_agree_on_rate(tmp_path):
    p = write(tmp_path, text(rows()))
    side = tmp_path / "ride.json"
    side.write_text("[1, 2]")
    with pytest.raises(LogFormatError, match="JSON object"):
        read_log(p)
    side.write_text('{\n "vehicle": "x",\n "sample_rate_hz": 50\n}')
    with pytest.raises(LogFormatError) as info:
        read_log(p)
    assert (info.value.path, info.value.line, info.value.column) == (side, 3, "sample_rate_hz")
    assert "100" in str(info.value)


def test_bad_min_duration_argument(tmp_path):
    p = write(tmp_path, text(rows()))
    with pytest.raises(LogDataError, match="min_duration_s"):
        read_log(p, min_duration_s=-1.0)
    with pytest.raises(TypeError):
        read_log(p, min_duration=1.0)


# --------------------------------------------------------------------------- writer checks


def test_overwrite_protection(tmp_path):
    cols = columns(150)
    p = write_log(tmp_path / "ride.csv", cols, meta={"notes": "first"})
    first = p.read_text()
    with pytest.raises(FileExistsError, match="ride.csv"):
        write_log(p, columns(150, seed=1))
    assert p.read_text() == first
    write_log(p, columns(150, seed=1), meta={"notes": "second"}, overwrite=True)
    assert p.read_text() != first and read_log(p).meta == {"notes": "second"}
    # a stale sidecar would be read with the new CSV: it counts as part of the log
    write_log(p, cols, overwrite=True)
    assert not (tmp_path / "ride.json").exists()
    (tmp_path / "other.json").write_text("{}")
    with pytest.raises(FileExistsError, match="other.json"):
        write_log(tmp_path / "other.csv", cols)
    assert not (tmp_path / "other.csv").exists()
    assert sorted(q.name for q in tmp_path.iterdir()) == ["other.json", "ride.csv"]  # no temp files left


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda c: c.pop("ay"), ["missing required column(s) ay"]),
        (lambda c: c.pop("t"), ["missing required column t"]),
        (lambda c: c.__setitem__("vx", np.ones(49)), ["'vx' has 49 samples, t has 50"]),
        (lambda c: c["tau"].__setitem__(3, np.inf), ["'tau' is infinite at sample 3"]),
        (lambda c: c["t"].__setitem__(10, c["t"][9]), ["column 't' at sample 10", "does not increase"]),
        (lambda c: c["t"].__setitem__(slice(10, None), c["t"][10:] + 0.01), ["sample 10", "non-uniform"]),
        (lambda c: c["t"].__setitem__(0, np.nan), ["t cannot be missing"]),
        (lambda c: c.__setitem__("a,b", np.ones(50)), ["'a,b'", "commas"]),
        (lambda c: c.__setitem__("ay", ["x"] * 50), ["'ay' is not numeric"]),
        (lambda c: c.__setitem__("ay", np.ones((50, 2))), ["one-dimensional"]),
    ],
)
def test_writer_validates_before_writing(tmp_path, change, words):
    cols = columns(50)
    change(cols)
    with pytest.raises(LogDataError) as info:
        write_log(tmp_path / "ride.csv", cols)
    for w in words:
        assert w in str(info.value)
    assert not list(tmp_path.iterdir())


def test_writer_checks_meta(tmp_path):
    with pytest.raises(LogDataError, match="sample_rate_hz = 50 disagrees"):
        write_log(tmp_path / "ride.csv", columns(50), meta={"sample_rate_hz": 50})
    with pytest.raises(LogDataError, match="not JSON-serialisable"):
        write_log(tmp_path / "ride.csv", columns(50), meta={"when": object()})
    with pytest.raises(LogDataError, match="sidecar"):
        write_log(tmp_path / "ride.json", columns(50))
    assert not list(tmp_path.iterdir())
    p = write_log(tmp_path / "ride.csv", columns(50), meta={"n": np.int64(3), "v": np.array([1.0, 2.0])})
    assert read_log(p, min_duration_s=0).meta == {"n": 3, "v": [1.0, 2.0]}
    with pytest.raises(TypeError):
        write_log(tmp_path / "x.csv", columns(50), overwite=True)


# --------------------------------------------------------------------------- cells that parse but are not data


@pytest.mark.parametrize(
    "column, cell, words",
    [
        ("vx", "nan", ["not a number", "dropout is an empty cell"]),
        ("roll_rate", "NaN", ["not a number"]),
        ("ay", "-inf", ["not finite"]),
        ("tau", "1_000", ["not a number", "ASCII"]),
        ("tau", "\u0661\u0662", ["not a number", "ASCII"]),  # Arabic-Indic digits: float() takes them
        ("delta", "\uff11", ["not a number"]),  # full-width 1
        ("ay", "-1e300", ["outside what a two-wheeler's sensor can read"]),
        ("vx", "200", ["outside", "[-170, 170] m/s"]),
        ("vx", "-200", ["outside", "[-170, 170] m/s"]),
        ("delta", "3.0", ["outside", "rad"]),
        ("roll_rate", "1e5", ["outside"]),
        ("vx", "\u00a0", ["not a number"]),  # a non-breaking space is text, not an empty cell
        ("ay", "\u00a01.5", ["not a number"]),
        ("tau", "\x0c", ["not a number"]),  # form feed: float() strips it, logs.md does not
    ],
)
def test_cells_that_float_accepts_but_are_not_data(tmp_path, column, cell, words):
    cells = rows()
    j = list(REQUIRED_COLUMNS).index(column)
    cells[30][j] = cell
    err = bad(tmp_path, text(cells))
    assert (err.line, err.column) == (32, column)
    for w in words:
        assert w in str(err), (w, str(err))


def test_an_extra_text_column_is_ignored_and_named(tmp_path):
    cells = rows()
    lines = text(cells).splitlines()
    lines = [lines[0] + ",comment,x_extra"] + [ln + f",lap {i},{i * 0.5}" for i, ln in enumerate(lines[1:])]
    log = read_log(write(tmp_path, "\n".join(lines) + "\n"))
    assert log.ignored_columns == ("comment",)
    assert "comment" not in log.columns and np.allclose(log["x_extra"], 0.5 * np.arange(len(log)))
    assert len(log) == len(cells)


def test_an_extra_column_with_text_late_in_the_file_is_ignored(tmp_path):
    cells = rows()
    lines = text(cells).splitlines()
    lines = [lines[0] + ",flag"] + [ln + (",1" if i < 50 else ",brake") for i, ln in enumerate(lines[1:])]
    log = read_log(write(tmp_path, "\n".join(lines) + "\n"))
    assert log.ignored_columns == ("flag",) and "flag" not in log.columns


def test_steer_angle_beyond_the_vehicles_lock_names_line_and_lock(tmp_path):
    import dataclasses

    from ptw_env.logs import check_against_vehicle
    from ptw_env.vehicle_files import load_vehicle

    cells = rows()
    j = list(REQUIRED_COLUMNS).index("delta")
    cells[40][j] = "0.8"  # 45.8 deg: within pi/2, beyond a 35 deg lock
    log = read_log(write(tmp_path, text(cells)))
    v = load_vehicle("sharp1971")
    check_against_vehicle(log, v)  # no lock in the file: only the geometric bound pi/2
    locked = dataclasses.replace(v, steer_lock=math.radians(35))
    with pytest.raises(LogFormatError) as e:
        check_against_vehicle(log, locked)
    assert (e.value.line, e.value.column) == (42, "delta")
    assert "steering lock" in str(e.value) and "35.0 deg" in str(e.value) and "45.8 deg" in str(e.value)
    assert log.where(40).endswith("line 42 (sample 40, t = 0.400 s)")


def test_the_one_held_speed_reconstruction_and_its_users():
    """A 10 Hz held GPS ramp with dropouts: fixes at each change, linear between them; the adaptive observer's,
    the diagnosis' (unsmoothed) and the risk warning's readers give the same numbers (one implementation)."""
    from assist.diagnose.data import reconstruct_speed
    from assist.estimation.adaptive_observer import gps_interpolate
    from ptw_env.logs import held_speed, sidecar_noise_pct, speed_fixes

    t = np.arange(0.0, 3.0, 0.01)
    true = 10.0 + 0.5 * t
    held = true[(np.arange(t.size) // 10) * 10]  # a fix every 0.1 s, held in between
    held[[33, 34, 155]] = np.nan  # dropouts between fixes (a dropped fix would be seen one sample late)
    tf, vf = speed_fixes(t, held)
    assert np.allclose(np.diff(tf), 0.1) and np.allclose(vf, 10.0 + 0.5 * tf)
    v = held_speed(t, held)
    inside = t <= tf[-1]
    assert np.allclose(v[inside], true[inside])  # exact on a ramp between the first and last fix
    assert np.array_equal(gps_interpolate(t, held), v)
    assert np.array_equal(reconstruct_speed(t, held, smooth_s=0.0), v)
    with pytest.raises(ValueError, match="no speed reading"):
        held_speed(t, np.full(t.size, np.nan))
    assert sidecar_noise_pct({"noise_pct": 2}) == 2.0 and sidecar_noise_pct({"noise_pct": True}) is None
    assert sidecar_noise_pct({}) is None and sidecar_noise_pct(None) is None


def test_observation_channels_by_name_match_the_environment():
    from ptw_env.env import OBS_NAMES, PTWRollEnv, obs_index

    env = PTWRollEnv("double_lane_change", noise_pct=0.0, observe_roll=True)
    obs, info = env.reset(seed=0)
    obs, *_ , info = env.step(np.zeros(1, dtype=np.float32))
    assert obs[obs_index("vx")[0]] == pytest.approx(info["vx"], abs=0.5)  # the held GPS speed
    assert obs[obs_index("phi_ref")[0]] == pytest.approx(info["phi_ref"], abs=1e-6)
    assert obs[obs_index("roll")[0]] == pytest.approx(info["state"][0], abs=1e-3)
    assert len(OBS_NAMES) == env.observation_space.shape[0]
    with pytest.raises(ValueError, match="unknown observation channel"):
        obs_index("speed")


def test_input_series_is_the_one_check_of_torque_and_speed():
    """ptw_env.logs.input_series: the held speed reconstructed (a dropout bridged), and one message per fault
    naming the first sample, its time, its file line and the count; used by the estimators, the adaptive
    observer and the risk warning (their messages are this one)."""
    import numpy as np

    from ptw_env.logs import input_series

    t = np.arange(6) * 0.01
    tau, v = input_series(t, np.zeros(6), [10.0, np.nan, 12.0, 12.0, 12.0, 12.0])  # fixes at t0 and t2
    np.testing.assert_allclose(v, [10.0, 11.0, 12.0, 12.0, 12.0, 12.0])
    with pytest.raises(ValueError, match=r"^f.csv: tau is missing at sample 2 \(t = 0.020 s, line 4 of a file"):
        input_series(t, [0, 0, np.nan, 0, np.nan, 0], np.full(6, 10.0), "f.csv")
    with pytest.raises(ValueError, match=r"vx = -1 m/s at sample 4 \(t = 0.040 s, line 6 .*\), 1 such sample"):
        input_series(t, np.zeros(6), [10, 10, 10, 10, -1, 10])
    with pytest.raises(ValueError, match="vx is missing at every sample"):
        input_series(t, np.zeros(6), np.full(6, np.nan))


# --------------------------------------------------------------------------- the ridden part of a real log


def test_ridden_part_keeps_the_longest_ridden_stretch_and_names_what_it_left_out(tmp_path):
    """Standstills (vx <= 0) and torque dropouts cut a log into usable stretches (issue 19: real logs are
    normal input for estimate and risk); the longest is kept, the rest named with file lines."""
    from ptw_env.logs import ridden_part

    cols = columns(600, seed=4)
    cols["vx"] = np.full(600, 5.0)
    cols["vx"][:50] = 0.0  # launched from a standstill
    cols["tau"][300] = np.nan  # a torque dropout
    cols["vx"][450:460] = -0.5  # pushed back
    cols["vx"][100] = np.nan  # a speed dropout is bridged, not a cut
    log = read_log(write_log(tmp_path / "ride.csv", cols))
    part, notes = ridden_part(log)
    assert len(part) == 250 and part.t[0] == log.t[50] and part.t[-1] == log.t[299]
    for c in log.columns:
        np.testing.assert_array_equal(part[c], log[c][50:300])
    assert "line 52" in part.where(0) and part.path == log.path
    assert "kept the longest ridden stretch" in notes[0] and "60 sample(s) with vx <= 0" in notes[0]
    assert "line 2 (sample 0" in notes[0] and "1 dropout(s) in tau" in notes[0] and "line 302 (sample 300" in notes[0]
    assert "2 shorter ridden stretch(es)" in notes[1] and "2.89 s in all" in notes[1]
    whole = read_log(write_log(tmp_path / "whole.csv", columns(300, seed=5) | {"vx": np.full(300, 3.0)}))
    assert ridden_part(whole) == (whole, [])
    from ptw_env.logs import MIN_DURATION_S, MIN_SAMPLES

    gap = int(round(0.8 * MIN_DURATION_S / 0.01))  # every stretch shorter than the shortest kept (100 Hz)
    cols["vx"][::gap] = 0.0
    with pytest.raises(LogDataError, match=rf"no ridden stretch of at least {MIN_DURATION_S:g} s and {MIN_SAMPLES} "
                                           rf"samples \(longest: {(gap - 1) * 0.01:.2f} s, {gap - 1} samples\)"):
        ridden_part(read_log(write_log(tmp_path / "short.csv", cols)))


@pytest.mark.parametrize("cmd", ["estimate", "risk"])
def test_estimate_and_risk_run_on_the_ridden_part_as_on_that_part_alone(tmp_path, capsys, cmd):
    """A real ride with standstills before and after (the robot bicycle's first run, padded with 1 s of
    vx = 0 each side): estimate and risk say what they left out and give the numbers of the ridden part
    written as a log of its own."""
    from assist.cli import main
    from ptw_env.logs import RideLog

    src = read_log(DATA / "robot_bicycle" / "rb_20130703_011.csv")
    n, pad = len(src), 100
    t = src.t[0] + np.arange(n + 2 * pad) * src.dt
    cols = {k: np.r_[np.full(pad, v[0]), v, np.full(pad, v[-1])] for k, v in src.columns.items() if k != "t"}
    cols["vx"][:pad] = 0.0
    cols["vx"][-pad:] = 0.0
    meta = {k: v for k, v in src.meta.items() if k != "vehicle_file"}
    padded = write_log(tmp_path / "padded.csv", RideLog(t=t, columns=cols, meta=meta))
    alone = write_log(tmp_path / "alone.csv", RideLog(t=t[pad:-pad], columns={k: v[pad:-pad] for k, v in cols.items()},
                                                       meta=meta))
    out = {}
    for name, path in (("padded", padded), ("alone", alone)):
        assert main([cmd, str(path), "--vehicle", "robot-bicycle", "--json", str(tmp_path / f"{name}_out.json")]) == 0
        out[name] = (json.loads((tmp_path / f"{name}_out.json").read_text()), capsys.readouterr().out)
    js, text = out["padded"]
    assert "note: kept the longest ridden stretch" in text and "200 sample(s) with vx <= 0" in js["notes"][0]
    assert not any("ridden stretch" in n for n in out["alone"][0].get("notes", []))
    assert js.get("notes", [])[1:] == out["alone"][0].get("notes", [])  # any other note (estimate: the band) alike
    keys = ("stiffness",) if cmd == "estimate" else ("mu_hat_final", "warnings")
    for k in keys:
        assert js[k] == out["alone"][0][k]
