"""Vehicle parameter files (TOML) and the vehicle presets.

A parameter file is plain TOML a person can read and edit: one table per
value with its unit and its source, grouped in sections. It is validated on
load; every problem ends in one :class:`VehicleFileError` naming the file, the
section and key, and what is wrong (with the line for TOML syntax errors).

File format
-----------
::

    name = "my-bike"                       # used in logs and figure titles
    description = "..."                    # optional
    layout = "whole_vehicle"               # or "sharp_frames" (ptw_env.sharp_geometry)
    references = ["...", "..."]            # optional, free text

    [speed_range]
    vmin = { value = 3.0, unit = "m/s", source = "..." }
    vmax = { value = 50.0, unit = "m/s", source = "..." }

    [geometry]
    caster = { value = 0.4715, unit = "rad", source = "Sharp 1971" }
    ...

Sections and their keys (which keys a layout needs: :data:`ptw_env.sharp_geometry.LAYOUTS`):

* ``[speed_range]``: ``vmin``, ``vmax`` [m/s], the valid forward-speed range, and optionally
  ``design_vmin``, ``design_vmax`` [m/s] (both or neither, within it), the default range of
  speed-scheduled designs (:attr:`ptw_env.vehicle.Vehicle.design_range`);
* ``[geometry]``: ``a, b, e, f, h, j, trail_normal, trail, caster, wheelbase, x_G, h_G``;
* ``[masses]``: ``M_f, M_r, M``;
* ``[inertias]``: ``I_fx, I_fz, I_rx, I_rz, C_rxz, I_xx, I_zz, C_xz``;
* ``[wheels]``: ``R_f, R_r, i_fy, i_ry``;
* ``[steering]``: ``K``;
* ``[tires]``: ``C_f1, C_f2, C_r1, C_r2, sigma_f, sigma_r`` and optionally ``Z_f``;
* ``[limits]`` (optional): ``steer_lock`` [rad] in ``(0, pi/2]``, the steering stops;
  a ride log steering beyond it is refused (:func:`ptw_env.logs.check_against_vehicle`;
  without it, only the geometric bound ``pi/2``).

Each value is ``{ value = <number>, unit = "<unit>", source = "<text>" }``.
Units are SI and must be written as expected (:data:`UNITS`; spaces, ``*``,
``·`` and ``^`` are ignored, so ``"kg m^2"`` = ``"kg*m^2"``): a caster in
``"deg"`` or a length in ``"mm"`` is refused with the converted value in the
message, not converted silently. Signs and ranges follow
:data:`ptw_env.sharp.SPECS` / :data:`ptw_env.sharp_geometry.LAYOUT_SPECS`
(masses > 0, caster in ``[0, pi/2)`` rad, ``Z_f < 0``, ...). Unknown or
misspelt keys are refused with the nearest known name.

Presets
-------
:func:`vehicle_names`: ``reference-scooter`` (the matrix form of model.md,
the default everywhere), ``sharp1971`` (Sharp's 1971 standard machine,
``vehicles/sharp1971.toml``) and ``cossalter-sport-touring`` (the sport-touring
motorcycle of Cossalter's *Motorcycle Dynamics*,
``vehicles/cossalter_sport_touring.toml``).

Examples
--------
>>> v = load_vehicle("sharp1971")
>>> v.name, v.vmin, v.vmax
('sharp1971', 3.0, 50.0)
>>> "sharp1971" in vehicle_names()
True
"""

from __future__ import annotations

import difflib
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from .sharp import SharpParameterError, SharpParameters, rule_violation, sharp_vehicle
from .sharp_geometry import LAYOUTS, layout_problems, sharp_parameters, spec
from .vehicle import REFERENCE_SCOOTER, Vehicle


class VehicleFileError(ValueError):
    """A vehicle parameter file or name that cannot be used; the message names file, key and problem."""


#: Section of each parameter key.
SECTIONS: dict[str, tuple[str, ...]] = {
    "speed_range": ("vmin", "vmax", "design_vmin", "design_vmax"),
    "geometry": ("a", "b", "e", "f", "h", "j", "trail_normal", "trail", "caster", "wheelbase", "x_G", "h_G"),
    "masses": ("M_f", "M_r", "M"),
    "inertias": ("I_fx", "I_fz", "I_rx", "I_rz", "C_rxz", "I_xx", "I_zz", "C_xz"),
    "wheels": ("R_f", "R_r", "i_fy", "i_ry"),
    "steering": ("K",),
    "tires": ("C_f1", "C_f2", "C_r1", "C_r2", "sigma_f", "sigma_r", "Z_f"),
    "limits": ("steer_lock",),
}
#: Keys that are not Table V parameters: (unit, meaning); checked here, not by ptw_env.sharp.SPECS.
_OWN_KEYS = {"vmin": ("m/s", "a forward speed"), "vmax": ("m/s", "a forward speed"),
             "design_vmin": ("m/s", "a forward speed"), "design_vmax": ("m/s", "a forward speed"),
             "steer_lock": ("rad", "the steering lock, in (0, pi/2]")}
_SECTION_OF = {k: sec for sec, keys in SECTIONS.items() for k in keys}
_TOP_LEVEL = ("name", "description", "layout", "references")
_ENTRY_FIELDS = ("value", "unit", "source")

#: Expected unit of each unit family, as written in files (compared with spaces, ``*``, ``·``, ``^`` removed).
UNITS = ("kg", "m", "rad", "kg m^2", "N m s/rad", "N/rad", "N", "m/s")

# factor from a common non-SI unit to the expected SI unit (only to make the error message useful)
_CONVERSIONS = {
    ("deg", "rad"): math.pi / 180, ("°", "rad"): math.pi / 180, ("degree", "rad"): math.pi / 180,
    ("degrees", "rad"): math.pi / 180,
    ("mm", "m"): 1e-3, ("cm", "m"): 1e-2, ("in", "m"): 0.0254, ("ft", "m"): 0.3048,
    ("g", "kg"): 1e-3, ("lb", "kg"): 0.45359237,
    ("km/h", "m/s"): 1 / 3.6, ("kph", "m/s"): 1 / 3.6,
    ("N/deg", "N/rad"): 180 / math.pi, ("kN/rad", "N/rad"): 1e3, ("kN", "N"): 1e3,
    ("Nms/deg", "Nms/rad"): 180 / math.pi, ("kgmm2", "kgm2"): 1e-6, ("kgcm2", "kgm2"): 1e-4,
}

#: Preset name -> packaged file (``None``: the reference scooter's matrix form).
#: Folder of the preset vehicle files (a vehicle from there is named by its preset name in a sidecar).
PRESET_DIR = Path(str(resources.files("ptw_env.vehicles"))).resolve()

PRESETS: dict[str, str | None] = {
    REFERENCE_SCOOTER.name: None,
    "sharp1971": "sharp1971.toml",
    "cossalter-sport-touring": "cossalter_sport_touring.toml",
    "robot-bicycle": "robot_bicycle.toml",
}
_ALIASES = {"reference": REFERENCE_SCOOTER.name, "robot_bicycle": "robot-bicycle",
            "cossalter_sport_touring": "cossalter-sport-touring", "reference_scooter": REFERENCE_SCOOTER.name}


def _norm_unit(u: str) -> str:
    return "".join(ch for ch in u if ch not in " *·^.")


def vehicle_names() -> tuple[str, ...]:
    """Names of the vehicle presets (:data:`PRESETS`), the reference scooter first."""
    return tuple(PRESETS)


def _suggest(word: str, choices: list[str] | tuple[str, ...]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


class _Reader:
    """Validates one parsed TOML document; every error names the file."""

    def __init__(self, path: Path, doc: dict[str, Any]):
        self.path, self.doc = path, doc

    def fail(self, where: str, what: str) -> VehicleFileError:
        return VehicleFileError(f"{self.path}: {where}{': ' if where else ''}{what}")

    def text(self, key: str, required: bool) -> str | None:
        v = self.doc.get(key)
        if v is None and not required:
            return None
        if not isinstance(v, str) or not v.strip():
            raise self.fail(key, "missing (a non-empty string)" if v is None else f"must be a non-empty string, got {v!r}")
        return v.strip()

    def entry(self, section: str, key: str, raw: Any) -> tuple[float, str]:
        where = f"[{section}] {key}"
        want = _OWN_KEYS[key][0] if key in _OWN_KEYS else spec(key).unit
        if not isinstance(raw, dict):
            raise self.fail(where, f"must be a table {{ value = ..., unit = \"{want}\", source = \"...\" }}, got {raw!r}")
        extra = [f for f in raw if f not in _ENTRY_FIELDS]
        if extra:
            raise self.fail(where, f"unknown field {extra[0]!r}{_suggest(extra[0], _ENTRY_FIELDS)}; "
                                   f"an entry has exactly value, unit, source")
        for f in _ENTRY_FIELDS:
            if f not in raw:
                raise self.fail(where, f"missing {f!r} (an entry has value, unit, source)")
        value, unit, source = raw["value"], raw["unit"], raw["source"]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(where, f"value must be a number, got {value!r}")
        if not isinstance(unit, str):
            raise self.fail(where, f"unit must be a string such as \"{want}\", got {unit!r}")
        if not isinstance(source, str) or not source.strip():
            raise self.fail(where, "source must say where the value comes from (a non-empty string)")
        if _norm_unit(unit) != _norm_unit(want):
            factor = _CONVERSIONS.get((_norm_unit(unit), _norm_unit(want)))
            hint = f": {value:g} {unit} = {value * factor:.6g} {want}" if factor and math.isfinite(value) else ""
            raise self.fail(where, f"unit {unit!r} given, {want!r} expected (SI units only; nothing is converted){hint}")
        rule, meaning = ("positive", _OWN_KEYS[key][1]) if key in _OWN_KEYS else (spec(key).rule, spec(key).meaning)
        why = rule_violation(float(value), rule)
        if not why and key == "steer_lock" and value > math.pi / 2:
            hint = f" (it looks like degrees: {value:g} deg = {math.radians(value):.4g} rad)" if value < 90.0 else ""
            why = f"must be at most pi/2 = {math.pi / 2:.4f}, got {value:g}{hint}"
        if why:
            raise self.fail(where, f"{why} ({meaning}, in {want})")
        return float(value), f"{value:g} {want}: {source.strip()}"

    def read(self) -> tuple[str, str, dict[str, float], dict[str, str], str | None]:
        """``(name, layout, values, provenance, description)``."""
        for key in self.doc:
            if key not in _TOP_LEVEL and key not in SECTIONS:
                hint = _suggest(key, list(_TOP_LEVEL) + list(SECTIONS))
                if key in _SECTION_OF and not isinstance(self.doc[key], dict):
                    hint = f" (it belongs in section [{_SECTION_OF[key]}])"
                raise self.fail(key, f"unknown top-level key{hint}; known: {', '.join(_TOP_LEVEL + tuple(SECTIONS))}")
        name = self.text("name", True)
        layout = self.text("layout", True)
        if layout not in LAYOUTS:
            raise self.fail("layout", f"unknown layout {layout!r}{_suggest(layout, list(LAYOUTS))}; known: {', '.join(LAYOUTS)}")
        description = self.text("description", False)
        refs = self.doc.get("references", [])
        if not isinstance(refs, list) or not all(isinstance(r, str) for r in refs):
            raise self.fail("references", f"must be a list of strings, got {refs!r}")
        values: dict[str, float] = {}
        prov: dict[str, str] = {}
        for section in self.doc:
            if section not in SECTIONS:
                continue
            body = self.doc[section]
            if not isinstance(body, dict):
                raise self.fail(f"[{section}]", f"must be a section (a TOML table), got {body!r}")
            for key, raw in body.items():
                if key not in SECTIONS[section]:
                    if key in _SECTION_OF:
                        raise self.fail(f"[{section}] {key}", f"belongs in section [{_SECTION_OF[key]}]")
                    raise self.fail(f"[{section}] {key}", f"unknown key{_suggest(key, list(_SECTION_OF))}; "
                                                          f"[{section}] takes {', '.join(SECTIONS[section])}")
                values[key], prov[key] = self.entry(section, key, raw)
        missing, conflicting = layout_problems(layout, set(values) - set(_OWN_KEYS))
        missing = [k for k in ("vmin", "vmax") if k not in values] + missing
        problems = []
        if missing:
            problems.append("missing " + ", ".join(f"[{_SECTION_OF[k.split(' or ')[0]]}] {k}" for k in missing))
        if conflicting:
            problems.append(f"cannot take {', '.join(conflicting)}")
        if problems:
            raise self.fail("", f"layout {layout!r}: " + "; ".join(problems))
        if not values["vmin"] < values["vmax"]:
            raise self.fail("[speed_range]", f"vmin = {values['vmin']:g} m/s must be below vmax = {values['vmax']:g} m/s")
        design = [k for k in ("design_vmin", "design_vmax") if k in values]
        if len(design) == 1:
            other = "design_vmax" if design[0] == "design_vmin" else "design_vmin"
            raise self.fail("[speed_range]", f"{design[0]} given without {other} (both or neither)")
        if design and not values["vmin"] <= values["design_vmin"] < values["design_vmax"] <= values["vmax"]:
            raise self.fail("[speed_range]", f"design_vmin = {values['design_vmin']:g}, design_vmax = "
                                             f"{values['design_vmax']:g} m/s must satisfy vmin <= design_vmin < "
                                             f"design_vmax <= vmax = [{values['vmin']:g}, {values['vmax']:g}]")
        if refs:
            prov["references"] = "; ".join(refs)
        return name, layout, values, prov, description


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise VehicleFileError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise VehicleFileError(f"{path}: is a directory, not a TOML file") from None
    except tomllib.TOMLDecodeError as exc:  # the message carries "(at line L, column C)"
        raise VehicleFileError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise VehicleFileError(f"{path}: not a UTF-8 text file ({exc.reason})") from None


def _resolve(name_or_path: str | Path) -> Path | None:
    """The file of a preset or path; ``None`` for the reference scooter."""
    key = _ALIASES.get(str(name_or_path), str(name_or_path))
    if key in PRESETS:
        fname = PRESETS[key]
        return None if fname is None else Path(str(resources.files("ptw_env.vehicles") / fname))
    p = Path(name_or_path)
    if p.suffix.lower() != ".toml" and not p.exists():
        raise VehicleFileError(f"unknown vehicle {str(name_or_path)!r}: not a preset "
                               f"({', '.join(vehicle_names())}) and no such file{_suggest(key, vehicle_names())}")
    return p


def _load(path: Path) -> tuple[SharpParameters, str, dict[str, float], dict[str, str]]:
    name, layout, values, prov, description = _Reader(path, _read_toml(path)).read()
    try:
        params = sharp_parameters(layout, {k: v for k, v in values.items() if k not in _OWN_KEYS})
    except SharpParameterError as exc:
        raise VehicleFileError(f"{path}: {exc}") from None
    prov = {"file": str(path), "layout": layout, **({"description": description} if description else {}), **prov}
    return params, name, values, prov


def load_parameters(name_or_path: str | Path) -> SharpParameters:
    """Table V's physical parameters of a preset or a parameter file.

    Raises
    ------
    VehicleFileError
        Unknown name, unreadable or invalid file (module docstring), or the
        reference scooter (given as matrix entries only, model.md).
    """
    path = _resolve(name_or_path)
    if path is None:
        raise VehicleFileError(f"{REFERENCE_SCOOTER.name} is given as matrix entries (model.md, Table IV), "
                               "not as physical parameters")
    return _load(path)[0]


def load_vehicle(name_or_path: str | Path) -> Vehicle:
    """A preset (:func:`vehicle_names`) or a TOML parameter file as a :class:`~ptw_env.vehicle.Vehicle`.

    Parameters
    ----------
    name_or_path : str or Path
        ``"reference-scooter"`` (alias ``"reference"``), another preset name,
        or the path of a parameter file (module docstring).

    Returns
    -------
    Vehicle
        The reference scooter itself, or the vehicle of
        :func:`ptw_env.sharp.sharp_vehicle` with the file's name, speed range
        and per-value sources as provenance.

    Raises
    ------
    VehicleFileError
        Unknown name or bad file; the message names the file, section, key
        and problem.
    """
    path = _resolve(name_or_path)
    if path is None:
        return REFERENCE_SCOOTER
    params, name, values, prov = _load(path)
    design = (values["design_vmin"], values["design_vmax"]) if "design_vmin" in values else None
    return sharp_vehicle(params, name=name, vmin=values["vmin"], vmax=values["vmax"], provenance=prov,
                         steer_lock=values.get("steer_lock", math.pi / 2), design_range=design)


def _normalised(name: str) -> str:
    key = _ALIASES.get(name, name)
    return key.strip().lower().replace("_", "-").replace(" ", "-")


def _same_vehicle(vname: Any, vehicle: Vehicle, path: Path) -> bool:
    """Whether a sidecar's ``vehicle`` names the vehicle its ``vehicle_file`` holds (by name or path)."""
    if not isinstance(vname, str) or not vname:
        return False
    if _normalised(vname) == _normalised(vehicle.name):
        return True
    cand = Path(vname)
    try:
        return cand.is_file() and cand.resolve() == path.resolve()
    except OSError:
        return False


def sidecar_vehicle(vehicle: Vehicle) -> dict[str, str]:
    """The sidecar keys that name ``vehicle`` (logs.md): ``vehicle`` (its name) and, for a user's vehicle file
    (not a preset), ``vehicle_file`` (its resolved path), so that :func:`vehicle_of_log` finds it again."""
    out = {"vehicle": vehicle.name}
    vfile = vehicle.provenance.get("file")
    if vfile and Path(vfile).resolve().parent != PRESET_DIR:
        out["vehicle_file"] = str(Path(vfile).resolve())
    return out


def vehicle_of_log(meta: Mapping[str, Any], log_path: str | Path | None = None) -> Vehicle | None:
    """The vehicle a ride log's sidecar names (logs.md ``vehicle``, optional ``vehicle_file``).

    ``vehicle_file`` wins when it can be found: as written, relative to the log's folder, or its
    file name beside the log (sidecars of data shipped in a folder with its vehicle file),
    and ``vehicle``, when also given, must name the same vehicle (its ``name``, case, ``_``
    and ``-`` aside, or the same file); else ``vehicle`` as a preset name or a file. ``None`` when the sidecar names no vehicle.

    Raises
    ------
    VehicleFileError
        The sidecar names a vehicle that is neither a preset nor a readable file; the
        message names the sidecar's key and value.
    """
    where = Path(log_path).with_suffix(".json") if log_path is not None else Path("sidecar")
    vfile, vname = meta.get("vehicle_file"), meta.get("vehicle")
    if vfile is not None:
        if not isinstance(vfile, str) or not vfile:
            raise VehicleFileError(f"{where}: 'vehicle_file' must be a path (a string), got {vfile!r}")
        base = Path(log_path).parent if log_path is not None else Path(".")
        for cand in (Path(vfile), base / vfile, base / Path(vfile).name):
            if cand.is_file():
                vehicle = load_vehicle(cand)
                if vname is not None and not _same_vehicle(vname, vehicle, cand):
                    raise VehicleFileError(
                        f"{where}: 'vehicle' = {vname!r} but 'vehicle_file' = {vfile!r} is the vehicle "
                        f"{vehicle.name!r} ({cand}): the sidecar names two different vehicles")
                return vehicle
    if vname is None:
        return None
    if not isinstance(vname, str) or not vname:
        raise VehicleFileError(f"{where}: 'vehicle' must be a preset name or a file (a string), got {vname!r}")
    try:
        return load_vehicle(vname)
    except VehicleFileError as exc:
        raise VehicleFileError(f"{where}: 'vehicle' = {vname!r}: {exc}") from None


__all__ = ["PRESETS", "PRESET_DIR", "SECTIONS", "UNITS", "VehicleFileError", "load_parameters", "load_vehicle", "vehicle_names",
           "sidecar_vehicle", "vehicle_of_log"]
