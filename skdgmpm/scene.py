"""Scenes: TOML files that read like a paper's problem statement, with units.

A scene names its grid (generated, or a mesh file read through meshio), material, particles,
initial state, boundary conditions by boundary name, method, end time, outputs and, when there is
one, the exact solution. Every key can be overridden (``--set method.cfl=0.5``). Every key, with
type, unit, default, example and the methods that read it: docs/scenes.md, generated from
`skdgmpm.scene_keys` (``skdgmpm scenes schema`` prints it); the scenes: ``cases/*.toml``.
"""
import copy
import tomllib
from dataclasses import dataclass, fields
from importlib import resources
from pathlib import Path

import numpy as np

from . import exact as exact_solutions
from .errors import InputError
from .materials import LAWS, make_material

NUMBER = (int, float)
# key -> expected type(s); a dict is a sub-table; None is a free-form table checked later
SCHEMA = {
    "title": str, "reference": str, "dim": int, "description": str,
    "grid": {"length": NUMBER, "cells": (int, list), "size": list, "origin": (list, NUMBER),
             "mesh": str},
    "body": {"box": dict, "subdomain": str, "ring": dict},
    "particles": {"per_cell": (int, list), "file": str},
    # the parameters of every registered law (make_material checks which ones a law takes)
    "material": {"law": str, **{f.name: NUMBER for cls in LAWS.values() for f in fields(cls) if f.init}},
    "regions": list,
    "initial": {"velocity": list, "F": list, "exact": bool, "field": dict},
    "boundaries": None,
    "bc": None,
    "method": {"name": str, "integrator": str, "transverse": str, "layout": str, "cfl": NUMBER, "order": int,
               "mls_order": int, "backmap": str, "limiter": str, "update": str, "shape": str,
               "time_step": str, "cfl_above_limit": bool, "cfl_guard": str, "geometry": str, "picard_max": int,
               "picard_tol": NUMBER},
    "run": {"t_end": NUMBER, "frames": int, "checkpoint_every": (int, str), "step_limit": int, "threads": int,
            "steps": (int, str),
            "energy_every": int, "fields": list},
    "exact": None,
    "probes": {"points": dict, "fields": list, "every": int},     # gauges: skdgmpm.probes
    "figures": {"times": list, "fields": list},     # paper times and fields of `skdgmpm compare-figures`
}
METHODS = ("dgmpm", "rk-dgfem", "ader-dgfem", "ader-dgmpm", "mpm")


def _where(source, key):
    return f"{source}: {key}" if source else key


def _check(table, schema, source, prefix=""):
    for key, value in table.items():
        path = f"{prefix}{key}"
        if key not in schema:
            known = ", ".join(f"{prefix}{k}" for k in schema)
            raise InputError(f"{_where(source, path)} is not a known key (known: {known})")
        expected = schema[key]
        if isinstance(expected, dict):
            if not isinstance(value, dict):
                raise InputError(f"{_where(source, path)} = {value!r} must be a table")
            _check(value, expected, source, path + ".")
        elif expected is None:
            if not isinstance(value, dict):
                raise InputError(f"{_where(source, path)} = {value!r} must be a table")
        elif not isinstance(value, expected) or (isinstance(value, bool) and expected is not bool):
            names = "/".join(t.__name__ for t in _flat_types(expected))
            raise InputError(f"{_where(source, path)} = {value!r} has the wrong type (expected {names})")


def _flat_types(expected):
    """(list, (int, float)) -> [list, int, float]."""
    if isinstance(expected, tuple):
        return [t for e in expected for t in _flat_types(e)]
    return [expected]


def parse_override(text):
    """'a.b=1e9' -> (['a', 'b'], 1e9); the value is read as TOML, else kept as a string."""
    if "=" not in text:
        raise InputError(f"--set {text!r}: expected KEY=VALUE")
    key, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key.strip().split("."), value


def apply_overrides(data, overrides, source="--set"):
    data = copy.deepcopy(data)
    for item in overrides:
        keys, value = parse_override(item) if isinstance(item, str) else item
        table = data
        for k in keys[:-1]:
            table = table.setdefault(k, {})
            if not isinstance(table, dict):
                raise InputError(f"{source} {'.'.join(keys)}: {k!r} is not a table")
        table[keys[-1]] = value
    return data


def scene_dirs():
    """Where scenes are looked up: ./cases in a checkout, then the installed package."""
    here = Path.cwd() / "cases"
    return [d for d in (here, Path(str(resources.files("skdgmpm.cases")))) if d.is_dir()]


def list_scenes():
    seen = {}
    for d in scene_dirs():
        for path in sorted(d.glob("*.toml")):
            seen.setdefault(path.stem, path)
    return seen


def find_scene(name):
    path = Path(name)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise InputError(f"{name}: scene file not found")
        return path
    scenes = list_scenes()
    if name not in scenes:
        raise InputError(f"scene {name!r} is unknown (known: {', '.join(scenes)})")
    return scenes[name]


def scene_files(name):
    """The files of a scene: its .toml and the files it reads (grid.mesh, particles.file), as
    (source path, path relative to the scene file's folder)."""
    path = find_scene(str(name))
    data = load_scene(path).data
    files = [(path, Path(path.name))]
    for key in ("grid.mesh", "particles.file"):
        table, leaf = key.split(".")
        relative = data.get(table, {}).get(leaf)
        if isinstance(relative, str):
            source = path.parent / relative
            if not source.is_file():
                raise InputError(f"{path}: {key} = {relative!r}: file {source} not found")
            if Path(relative).is_absolute() or ".." in Path(relative).parts:
                raise InputError(f"{path}: {key} = {relative!r} is outside the scene's folder: copy it by hand")
            files.append((source, Path(relative)))
    return files


def copy_scene(name, folder, force=False):
    """Copy scene ``name`` with the files it reads into ``folder`` (created), so that
    ``skdgmpm run FOLDER/NAME.toml`` runs it from there. Refuses, before copying anything, to
    overwrite an existing file unless ``force``. Returns the paths written."""
    import shutil

    folder = Path(folder)
    files = scene_files(name)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder}: exists and is not a directory")
    existing = [str(folder / rel) for _, rel in files if (folder / rel).exists()]
    if existing and not force:
        raise InputError(f"{', '.join(existing)}: exists already (use --force to overwrite)")
    written = []
    try:
        for source, rel in files:
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, folder / rel)
            written.append(folder / rel)
    except OSError as exc:
        raise InputError(f"{folder}: cannot copy the scene ({exc.strerror or exc})") from None
    return written


@dataclass
class Scene:
    """A validated scene: the raw tables plus where they came from."""

    name: str
    data: dict
    path: Path = None
    overridden: tuple = ()      # dotted keys given with --set (they, not the file, are blamed)

    def get(self, dotted, default=None):
        table = self.data
        for k in dotted.split("."):
            if not isinstance(table, dict) or k not in table:
                return default
            table = table[k]
        return table

    def where(self, key):
        """Where ``key`` comes from, for messages: "FILE: key"; "--set key" when --set gave it (or
        a table holding it); "FILE with --set a.b=...: key" when --set changed a key inside it."""
        source = str(self.path) if self.path else self.name
        if any(key == k or key.startswith(k + ".") or key.startswith(k + "[") for k in self.overridden):
            return f"--set {key}"
        inside = [k for k in self.overridden if k.startswith(key + ".")]
        if inside:
            return f"{source} with --set {', '.join(inside)}: {key}"
        return _where(source, key)

    @property
    def dim(self):
        return self.data["dim"]

    def resolve(self, relative):
        base = self.path.parent if self.path else Path.cwd()
        return base / relative

    def with_overrides(self, overrides):
        data = apply_overrides(self.data, overrides)
        _check(apply_overrides({}, overrides), SCHEMA, "--set")   # errors name --set, not the file
        keys = [".".join(parse_override(o)[0] if isinstance(o, str) else o[0]) for o in overrides]
        scene = Scene.from_dict(data, self.name, self.path)
        scene.overridden = tuple(dict.fromkeys((*self.overridden, *keys)))
        return scene

    @classmethod
    def from_dict(cls, data, name="scene", path=None):
        source = str(path) if path else name
        _check(data, SCHEMA, source)
        for key in ("dim", "grid", "material", "method", "run"):
            if key not in data:
                raise InputError(f"{_where(source, key)} is missing")
        if data["dim"] not in (1, 2):
            raise InputError(f"{_where(source, 'dim')} = {data['dim']!r} must be 1 or 2")
        if data["method"].get("name", "dgmpm") not in METHODS:
            raise InputError(f"{_where(source, 'method.name')} = {data['method']['name']!r}: "
                             f"expected one of {', '.join(METHODS)}")
        return cls(name, data, path)


def load_scene(name, overrides=()):
    """Load a scene by name (from ``cases/``) or path, apply ``--set`` style overrides."""
    path = find_scene(str(name))
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a UTF-8 text file (byte {exc.object[exc.start]:#04x} at offset "
                         f"{exc.start}); TOML scene files are UTF-8") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the scene file ({exc.strerror or exc})") from None
    scene = Scene.from_dict(data, path.stem, path)
    return scene.with_overrides(overrides) if overrides else scene


def exact_solution(scene):
    """The scene's exact solution object, its parameters taken from the scene itself."""
    spec = scene.get("exact")
    if not spec:
        return None
    spec = dict(spec)
    name = spec.pop("name", None)
    mat = scene.data["material"]
    params = {"E": mat.get("E"), "rho": mat.get("rho")}
    if name in exact_solutions.MANUFACTURED:             # any law: the scene's own material object
        law = dict(mat)
        try:
            params = {"material": make_material(law.pop("law", "linear_elastic"), **law)}
        except InputError as exc:
            raise InputError(f"{scene.where('material')}: {str(exc).removeprefix('material: ')}") from None
        if name == "mms_ring":
            params.update(scene.get("body.ring") or {})  # the ring that holds the particles
    if name in ("svk_bar_riemann", "standing_wave_2d", "elastoplastic_bar_step", "square_shear_mode"):
        params["nu"] = mat.get("nu")
    if name == "elastoplastic_bar_step":                 # yield and hardening: the law's, or [exact]'s
        params.update({k: mat[k] for k in ("sigma_y", "H") if k in mat})
    if name == "standing_wave_2d":
        params["size"] = tuple(scene.get("grid.size", (1.0, 1.0)))
    if "load" in spec:                                   # P11 = t . N with N = -e1 at the left end
        load = spec.pop("load")
        bc = scene.get(f"bc.{load}") if isinstance(load, str) else None
        if not isinstance(bc, dict):
            raise InputError(f"{scene.where('exact.load')} = {load!r}: no [bc.{load}] table in the scene")
        if bc.get("kind") not in ("traction", "free"):
            raise InputError(f"{scene.where('exact.load')} = {load!r}: bc.{load} must be of kind "
                             f"'traction' or 'free', not {bc.get('kind')!r}")
        params["traction"] = -float(np.atleast_1d(bc.get("value", [0.0]))[0])
    if name in ("elastic_bar_step", "elastoplastic_bar_step"):
        params["length"] = scene.get("grid.length", scene.get("grid.size", [None])[0])
    params.update(spec)
    try:
        return exact_solutions.make_exact(name, **params)
    except InputError as exc:
        raise InputError(f"{scene.where('exact')}: {exc}") from None
