"""Dotted paths into scenes, effective scenes and the TOML writer (pure Python)."""

import tomllib

import pytest

from batch_helpers import BAR, CONFIGS
from parsolve.batch.scene_edit import effective_scene, set_path, split_path
from parsolve.batch.toml_write import dumps


def test_split_path():
    assert split_path("mesh.nx") == ["mesh", "nx"]
    assert split_path("materials[0].E") == ["materials", 0, "E"]
    assert split_path("relations[2].direction[1]") == ["relations", 2, "direction", 1]
    for bad in ["", "a..b", "[0]", "a.", "a[x]", ".a", "a b"]:
        with pytest.raises(ValueError):
            split_path(bad)


def test_set_path_replaces_and_reports_missing():
    data = {"mesh": {"nx": 1}, "materials": [{"E": 1.0}], "loads": [{"total_force": [1.0, 0.0]}]}
    set_path(data, "mesh.nx", 7)
    set_path(data, "materials[0].E", 2.5)
    set_path(data, "loads[0].total_force[1]", -3.0)
    set_path(data, "mesh.order", 2)  # a new last key (validation decides whether it is known)
    assert data == {"mesh": {"nx": 7, "order": 2}, "materials": [{"E": 2.5}],
                    "loads": [{"total_force": [1.0, -3.0]}]}
    for path in ["materials[1].E", "model.hypothesis", "mesh.nx.y", "loads[0].total_force[2]"]:
        with pytest.raises(KeyError):
            set_path(data, path, 0)


@pytest.mark.parametrize("name", sorted(p.name for p in CONFIGS.glob("*.toml")))
def test_writer_round_trips_every_shipped_scene(name):
    data = tomllib.loads((CONFIGS / name).read_text())
    assert tomllib.loads(dumps(data)) == data


def test_writer_values():
    data = {"a": 1, "b": -2.5e-300, "c": float("inf"), "d": "q\"uo\\te\n", "e": [1, [2, 3]],
            "f": True, "g": {"x y": {"z": 1}}, "h": [{"k": 1}, {"k": 2, "m": {"n": 3}}],
            "i": [1.0, {"p": 2}]}
    assert tomllib.loads(dumps(data)) == data


def test_effective_scene_changes_and_absolute_mesh_file(tmp_path):
    text = effective_scene(BAR, {"mesh.nx": 5, "materials[0].E": 3e9}, header="batch run 1")
    data = tomllib.loads(text)
    base = tomllib.loads(BAR.read_text())
    base["mesh"]["nx"], base["materials"][0]["E"] = 5, 3e9
    assert data == base and text.startswith("# batch run 1\n")
    (tmp_path / "sub").mkdir()
    scene = tmp_path / "sub" / "scene.toml"
    scene.write_text(BAR.read_text().replace('generator = "rectangle"', 'file = "mesh.msh"'))
    data = tomllib.loads(effective_scene(scene, {}))
    assert data["mesh"]["file"] == str(tmp_path / "sub" / "mesh.msh")
    # a mesh file set by a change is relative to where the change was written
    data = tomllib.loads(effective_scene(scene, {"mesh.file": "other.msh"}, relative_to=tmp_path))
    assert data["mesh"]["file"] == str(tmp_path / "other.msh")
