"""Vehicle parameter files and presets: loading, validation errors, and `ptw-assist modes --vehicle`.

Each bad file is the packaged sharp1971.toml with one deliberate mistake; the
error must be one clear line naming the file, the section and key, and what
is wrong (never a traceback from deep inside, never a silent fix).
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from assist.cli import main
from ptw_env.vehicle import REFERENCE_SCOOTER
from ptw_env.vehicle_files import VehicleFileError, load_parameters, load_vehicle, vehicle_names

SHARP_TOML = (resources.files("ptw_env.vehicles") / "sharp1971.toml").read_text()


def _write(tmp_path: Path, text: str, name: str = "bike.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _edit(old: str, new: str) -> str:
    assert SHARP_TOML.count(old) == 1, old
    return SHARP_TOML.replace(old, new)


# ----------------------------------------------------------------------------- presets
def test_presets():
    assert vehicle_names() == ("reference-scooter", "sharp1971", "cossalter-sport-touring", "robot-bicycle")
    assert load_vehicle("reference-scooter") is REFERENCE_SCOOTER
    assert load_vehicle("reference") is REFERENCE_SCOOTER
    for name in vehicle_names()[1:]:
        v = load_vehicle(name)
        assert v.name == name and v.vmin < v.vmax
        assert all(src for key, src in v.provenance.items())
    with pytest.raises(VehicleFileError, match="matrix entries"):
        load_parameters("reference-scooter")


def test_a_copied_file_gives_the_same_vehicle(tmp_path):
    v0 = load_vehicle("sharp1971")
    v1 = load_vehicle(_write(tmp_path, SHARP_TOML))
    for m in ("E", "A0", "A1", "B"):
        assert np.array_equal(getattr(v0, m), getattr(v1, m))
    assert v1.tires == v0.tires
    assert str(tmp_path / "bike.toml") == v1.provenance["file"]


def test_equivalent_unit_spellings_are_accepted(tmp_path):
    text = _edit('I_fx = { value = 1.2338, unit = "kg m^2"', 'I_fx = { value = 1.2338, unit = "kg*m^2"')
    text = text.replace('unit = "N m s/rad"', 'unit = "N·m·s/rad"')
    assert np.array_equal(load_vehicle(_write(tmp_path, text)).E, load_vehicle("sharp1971").E)


# ----------------------------------------------------------------------------- errors
BAD = [
    # (old, new, words the message must contain)
    ('M_f = { value = 30.65,', 'M_f = { value = -30.65,', ["[masses] M_f", "must be > 0", "-30.65"]),
    ('I_fz = { value = 0.4420, unit = "kg m^2", source = "Sharp 1971, standard machine" }\n', "",
     ["missing [inertias] I_fz"]),
    ('caster = { value = 0.4715, unit = "rad"', 'caster = { value = 27.0, unit = "deg"',
     ["[geometry] caster", "unit 'deg' given, 'rad' expected", "27 deg = 0.471239 rad"]),
    ('caster = { value = 0.4715, unit = "rad"', 'caster = { value = 27.0, unit = "rad"',
     ["[geometry] caster", "radians", "looks like degrees", "27 deg = 0.4712 rad"]),
    ('h = { value = 0.6157, unit = "m"', 'h = { value = 615.7, unit = "mm"',
     ["[geometry] h", "'mm' given, 'm' expected", "0.6157 m"]),
    ('C_rxz = {', 'C_rzx = {', ["[inertias] C_rzx", "unknown key", "did you mean 'C_rxz'"]),
    ('[steering]\nK = {', '[steering]\nsigma_f = { value = 0.2, unit = "m", source = "x" }\nK = {',
     ["[steering] sigma_f", "belongs in section [tires]"]),
    ('Z_f = { value = -1005.3,', 'Z_f = { value = 1005.3,', ["[tires] Z_f", "must be < 0"]),
    ('Z_f = { value = -1005.3,', 'Z_f = { value = -100.53,', ["Z_f = -100.53 N disagrees with the static front load"]),
    ('K = { value = 6.77, unit = "N m s/rad", source = "Sharp 1971, standard machine: steering damper" }',
     'K = { value = 6.77, unit = "N m s/rad" }', ["[steering] K", "missing 'source'"]),
    ('K = { value = 6.77, unit = "N m s/rad", source = "Sharp 1971, standard machine: steering damper" }',
     'K = { value = 6.77, unit = "N m s/rad", source = "" }', ["[steering] K", "source must say"]),
    ('K = { value = 6.77,', 'K = { value = "6.77",', ["[steering] K", "value must be a number"]),
    ('K = { value = 6.77,', 'K = { value = true,', ["[steering] K", "value must be a number"]),
    ('K = { value = 6.77,', 'K = { value = 6.77, units = "x",', ["[steering] K", "unknown field 'units'"]),
    ('K = { value = 6.77,', 'K = 6.77\nX = { value = 6.77,', ["[steering] K", "must be a table"]),
    ('layout = "sharp_frames"', 'layout = "sharp-frames"', ["layout", "unknown layout", "did you mean 'sharp_frames'"]),
    ('layout = "sharp_frames"', 'layout = "whole_vehicle"',
     ["layout 'whole_vehicle': missing", "[masses] M,", "cannot take", "a (not used by layout 'whole_vehicle')"]),
    ('vmax = { value = 50.0,', 'vmax = { value = 2.0,', ["[speed_range]", "vmin = 3 m/s must be below vmax = 2 m/s"]),
    ('name = "sharp1971"', 'name = "sharp1971"\nlayuot = "x"', ["layuot", "unknown top-level key", "did you mean 'layout'"]),
    ('C_rxz = { value = -1.7355,', 'C_rxz = { value = 60.0,', ["positive definite"]),
]


@pytest.mark.parametrize("old, new, words", BAD, ids=[w[0] for _, _, w in BAD])
def test_bad_file_one_clear_error(tmp_path, old, new, words):
    path = _write(tmp_path, _edit(old, new))
    with pytest.raises(VehicleFileError) as exc:
        load_vehicle(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}:") and "\n" not in msg
    for w in words:
        assert w in msg, msg


def test_toml_syntax_error_gives_the_line(tmp_path):
    text = _edit('h = { value = 0.6157,', 'h = { value = 0.6157')
    line = text.splitlines().index(next(ln for ln in text.splitlines() if ln.startswith("h = {"))) + 1
    with pytest.raises(VehicleFileError) as exc:
        load_vehicle(_write(tmp_path, text))
    assert "not valid TOML" in str(exc.value) and f"line {line}" in str(exc.value)


def test_unknown_names_and_missing_files(tmp_path):
    with pytest.raises(VehicleFileError, match="unknown vehicle 'sharp1917'.*did you mean 'sharp1971'"):
        load_vehicle("sharp1917")
    with pytest.raises(VehicleFileError, match="no such file"):
        load_vehicle(tmp_path / "nope.toml")
    binary = tmp_path / "b.toml"
    binary.write_bytes(b"\xff\xfe\x00name")
    with pytest.raises(VehicleFileError, match="not"):
        load_vehicle(binary)
    with pytest.raises(VehicleFileError, match="is a directory"):
        load_vehicle(tmp_path)


# ----------------------------------------------------------------------------- CLI
@pytest.mark.parametrize("name", vehicle_names())
def test_modes_cli_every_preset(tmp_path, capsys, name):
    js = tmp_path / "m.json"
    v = load_vehicle(name)
    speeds = [float(x) for x in np.round(np.linspace(v.vmin, v.vmax, 5)[1:4], 1)]  # inside its own range
    assert main(["modes", "--vehicle", name, "--speeds", ",".join(map(str, speeds)), "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    assert d["speeds"] == speeds
    for s, evs in zip(d["speeds"], d["eigenvalues"]):
        ours = np.sort_complex(np.array([complex(*e) for e in evs]))
        ref = np.sort_complex(np.linalg.eigvals(v.state_matrix(s)))
        assert np.allclose(ours, ref, rtol=1e-9, atol=1e-9)
    assert f"{name}: weave stability speed" in capsys.readouterr().out


def test_modes_cli_file_and_root_locus(tmp_path, capsys):
    path = _write(tmp_path, SHARP_TOML)
    png = tmp_path / "locus.png"
    assert main(["modes", "--vehicle", str(path), "--speeds", "3,6,10,20,40", "--locus", str(png)]) == 0
    out = capsys.readouterr().out
    assert "sharp1971: weave stability speed 5.89 m/s" in out
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize(
    "vehicle, speeds, words",
    [
        ("sharp1917", "5", ["--vehicle", "unknown vehicle 'sharp1917'"]),
        ("{bad}", "5", ["--vehicle", "bad.toml", "[masses] M_f", "must be > 0"]),
        ("sharp1971", "55", ["--speeds", "valid range [3.0, 50.0] m/s of sharp1971"]),
    ],
)
def test_modes_cli_bad_vehicle_one_line_exit_2(tmp_path, capsys, vehicle, speeds, words):
    bad = _write(tmp_path, _edit('M_f = { value = 30.65,', 'M_f = { value = -30.65,'), "bad.toml")
    rc = main(["modes", "--vehicle", vehicle.replace("{bad}", str(bad)), "--speeds", speeds])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and err.startswith("ptw-assist modes: error:")
    for w in words:
        assert w in err, err


# ----------------------------------------------------------------------------- steering lock, sidecars
def test_steer_lock_from_the_file_in_radians_only(tmp_path):
    import math

    assert load_vehicle("sharp1971").steer_lock == math.pi / 2  # no [limits]: the geometric bound
    ok = _write(tmp_path, SHARP_TOML + '\n[limits]\nsteer_lock = { value = 0.6, unit = "rad", source = "test" }\n')
    v = load_vehicle(ok)
    assert v.steer_lock == 0.6 and v.identity()["model_sha256"] == load_vehicle("sharp1971").identity()["model_sha256"]
    deg = _write(tmp_path, SHARP_TOML + '\n[limits]\nsteer_lock = { value = 35, unit = "rad", source = "x" }\n', "d.toml")
    with pytest.raises(VehicleFileError, match=r"\[limits\] steer_lock.*at most pi/2.*35 deg = 0.6109 rad"):
        load_vehicle(deg)


def test_a_sidecar_naming_two_different_vehicles_is_refused(tmp_path):
    from ptw_env.vehicle_files import vehicle_of_log

    path = _write(tmp_path, SHARP_TOML)
    log = tmp_path / "ride.csv"
    assert vehicle_of_log({"vehicle": "sharp1971", "vehicle_file": str(path)}, log).name == "sharp1971"
    assert vehicle_of_log({"vehicle": str(path), "vehicle_file": "bike.toml"}, log).name == "sharp1971"
    with pytest.raises(VehicleFileError, match=r"'vehicle' = 'no-such-bike'.*'sharp1971'.*two different vehicles"):
        vehicle_of_log({"vehicle": "no-such-bike", "vehicle_file": str(path)}, log)
    rb = Path(__file__).resolve().parents[2] / "shared" / "data" / "robot_bicycle"
    if rb.is_dir():  # the shipped sidecars: 'robot_bicycle' names the file's vehicle 'robot_bicycle'
        meta = json.loads(next(rb.glob("*.json")).read_text())
        assert vehicle_of_log(meta, next(rb.glob("*.csv"))).name == "robot_bicycle"


@pytest.mark.parametrize("name", vehicle_names())
def test_modes_default_speeds_span_the_vehicles_own_range(tmp_path, name):
    js = tmp_path / "m.json"
    v = load_vehicle(name)
    assert main(["modes", "--vehicle", name, "--json", str(js)]) == 0
    sp = json.loads(js.read_text())["speeds"]
    assert len(sp) == 5 and sp[0] == pytest.approx(v.vmin) and sp[-1] == pytest.approx(v.vmax)
