"""docs/scenes.md against the scene schema: every key documented, the file the generated text.

The table lives in skdgmpm/scene_keys.py; ``skdgmpm scenes schema --markdown > docs/scenes.md``
writes the file. A key added to `skdgmpm.scene.SCHEMA`, to a law, to an exact solution or used by a
shipped scene without a row in the table fails here.
"""
import tomllib
import warnings
from dataclasses import fields
from pathlib import Path

import pytest

from skdgmpm import scene_keys
from skdgmpm.build import build
from skdgmpm.exact import EXACT, INITIAL
from skdgmpm.materials import LAWS
from skdgmpm.run import run
from skdgmpm.scene import list_scenes, load_scene

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTED = set(scene_keys.BY_NAME)


def test_docs_scenes_md_is_the_generated_text():
    assert (ROOT / "docs" / "scenes.md").read_text(encoding="utf-8") == scene_keys.markdown(), \
        "docs/scenes.md is stale: skdgmpm scenes schema --markdown > docs/scenes.md"


def test_every_schema_key_is_documented():
    for path, expected in scene_keys.schema_paths():
        if expected is None or path == "regions":          # a free-form table, the list [[regions]]
            assert any(k.startswith(path + ".") or k.startswith(path + "[") for k in DOCUMENTED), path
        else:
            assert path in DOCUMENTED, f"{path} is in scene.SCHEMA but not in scene_keys.KEYS"


def test_no_row_without_a_schema_key():
    schema = {path for path, _ in scene_keys.schema_paths()}
    for name in DOCUMENTED:
        head = name.split("[")[0]
        assert any(name == p or head == p or name.startswith(p + ".") for p in schema), name


def test_every_law_parameter_and_exact_parameter_is_documented():
    for cls in LAWS.values():
        for f in fields(cls):
            if f.init:
                assert f"material.{f.name}" in DOCUMENTED, (cls.__name__, f.name)
    from_scene = {"E", "nu", "rho", "material"}             # taken from [material]
    for cls in EXACT.values():
        for f in fields(cls):
            if f.init and f.name not in from_scene:
                assert f"exact.{f.name}" in DOCUMENTED, (cls.__name__, f.name)
    for cls in INITIAL.values():
        for f in fields(cls):
            assert f"initial.field.{f.name}" in DOCUMENTED, (cls.__name__, f.name)
    assert "gavrilyuk" in scene_keys.BY_NAME["material.law"].means


def _keys(table, prefix=""):
    for key, value in table.items():
        path = prefix + key
        if prefix in ("bc.", "boundaries."):
            path = prefix + "NAME"
        if key == "regions":
            for region in value:
                yield from (f"regions[].{k}" for k in region)
        elif isinstance(value, dict) and path + ".*" not in ("initial.field.*",) and path not in (
                "body.box", "body.ring", "initial.field", "bc.NAME.velocity", "bc.NAME.traction",
                "boundaries.NAME.box"):
            yield from _keys(value, path + ".")
        else:
            yield path


@pytest.mark.parametrize("name", sorted(list_scenes()))
def test_every_key_of_a_shipped_scene_is_documented(name):
    data = tomllib.loads(list_scenes()[name].read_text(encoding="utf-8"))
    for key in _keys(data):
        assert key in DOCUMENTED, f"{name}: {key}"


def test_the_keys_asked_for_in_issue_18_are_there():
    for key in ("material.a", "initial.velocity", "initial.F", "initial.exact", "initial.field", "particles.file",
                "body.ring", "figures.times", "figures.fields", "regions[].subdomain"):
        row = {k.name: k for k in scene_keys.rows()}[key]
        assert row.type and row.default and row.example and row.means, key


def test_schema_types_come_from_the_schema():
    rows = {k.name: k for k in scene_keys.rows()}
    assert rows["method.cfl"].type == "number" and rows["grid.cells"].type == "integer or list"
    assert rows["method.cfl_above_limit"].type == "boolean" and rows["body.ring"].type == "table"


# ------------------------------------------------------------------ keys a method does not read

def _warnings(scene, overrides):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        build(load_scene(scene, overrides))
    return [str(w.message) for w in caught]


def test_ader_run_warns_that_it_ignores_integrator_and_transverse():
    said = _warnings("partial_impact_2d", ['method.name="ader-dgmpm"', "method.cfl=0.2", "particles.per_cell=[0.25, 0.75]",
                                           'method.integrator="rk2"', 'method.transverse="dcu"'])
    assert any("--set method.integrator = 'rk2' is ignored by ader-dgmpm (read by dgmpm, rk-dgfem)" in m
               for m in said), said
    assert any("method.transverse = 'dcu' is ignored by ader-dgmpm" in m for m in said), said
    assert all("\n" not in m for m in said)


def test_ader_scene_file_with_an_integrator_warns(tmp_path):
    text = (ROOT / "cases" / "lasat_2d.toml").read_text().replace('name = "ader-dgmpm"',
                                                                      'name = "ader-dgmpm"\nintegrator = "rk2"')
    (tmp_path / "s.toml").write_text(text)
    (tmp_path / "lasat_30.msh").write_bytes((ROOT / "cases" / "lasat_30.msh").read_bytes())
    said = _warnings(tmp_path / "s.toml", [])
    assert any(m.endswith("s.toml: method.integrator = 'rk2' is ignored by ader-dgmpm (read by dgmpm, rk-dgfem)")
               for m in said), said


def test_1d_dgmpm_warns_about_transverse_and_summary_says_none():
    said = _warnings("bar_elastic_1d", ['method.transverse="ctu"'])
    assert any("method.transverse = 'ctu' is ignored in 1D" in m for m in said), said
    r = run("bar_elastic_1d", ["grid.cells=20", "run.t_end=1e-4"], progress=False)
    assert r.summary()["transverse"] == "none"


def test_switching_the_method_with_set_does_not_warn_about_the_files_keys():
    """The studies run a scene's file with --set method.name=...: the file's integrator belongs to
    its own method and is not the user's mistake."""
    said = _warnings("partial_impact_2d", ['method.name="ader-dgfem"', "method.cfl=0.2", "grid.cells=[8, 6]"])
    assert not any("ignored" in m for m in said), said


def test_shipped_scenes_ask_for_nothing_their_method_ignores():
    for name in list_scenes():
        scene = load_scene(name)
        assert scene_keys.ignored_keys(scene) == [], name
