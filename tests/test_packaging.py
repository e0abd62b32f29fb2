"""Packaging: the model library ships with the package and the dependencies are ranges.

The repository keeps the model files at its top (``models/``); pyproject.toml maps them into the
package as ``bayes_roadload/models``.  The fast tests check the lookup and the configuration;
the wheel test builds the wheel (pip with build isolation, about 30 s, needs the build backend
from the index or pip's cache) and is marked slow: .ci/run installs the built wheel into a fresh
venv and runs the demo from it on every run.
"""

import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from packaging.requirements import Requirement

import bayes_roadload
from bayes_roadload.analysis.effects import LIBRARY_PATH, load_library
from bayes_roadload.inference.spec import MODELS_DIR, available_models, load_model_spec

REPO = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
MODEL_FILES = sorted((REPO / "models").glob("*.toml"))
LIBRARY_FILE = REPO / "models" / "effects" / "library.toml"


def test_available_models_lists_every_model_file_of_the_repository():
    assert MODEL_FILES, "the repository has no models/*.toml"
    assert available_models() == [p.stem for p in MODEL_FILES]


def test_bare_model_names_and_the_effect_library_resolve_in_the_model_library():
    for p in MODEL_FILES:
        spec = load_model_spec(p.stem)
        assert spec.source == str(MODELS_DIR / p.name)
        assert (MODELS_DIR / p.name).read_bytes() == p.read_bytes()
    assert LIBRARY_PATH == MODELS_DIR / "effects" / "library.toml"
    assert LIBRARY_PATH.read_bytes() == LIBRARY_FILE.read_bytes()
    assert load_library()  # parses and is not empty


def test_pyproject_lists_every_package_and_maps_the_model_library():
    setuptools = PYPROJECT["tool"]["setuptools"]
    on_disk = {".".join(p.parent.relative_to(REPO).parts) for p in (REPO / "bayes_roadload").rglob("__init__.py")}
    listed = set(setuptools["packages"])
    missing = on_disk - listed
    assert not missing, f"pyproject.toml [tool.setuptools] packages lacks {sorted(missing)}: not in the wheel"
    assert setuptools["package-dir"]["bayes_roadload.models"] == "models"
    assert {"bayes_roadload.models", "bayes_roadload.models.effects"} <= listed
    data = setuptools["package-data"]
    assert "*.toml" in data["bayes_roadload.models"] and "*.toml" in data["bayes_roadload.models.effects"]


def test_runtime_dependencies_are_ranges_not_pins():
    project = PYPROJECT["project"]
    pinned = [d for d in project["dependencies"] if "==" in d]
    assert not pinned, f"pinned runtime dependencies (exact versions belong in constraints.txt): {pinned}"
    assert project["requires-python"].startswith(">=") and "<" not in project["requires-python"]


def test_constraints_file_pins_every_runtime_dependency_inside_its_range():
    locked = {}
    for line in (REPO / "constraints.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, _, version = line.partition("==")
            assert version, f"constraints.txt: {line!r} is not an exact pin"
            locked[name.lower().replace("_", "-")] = version
    for dep in PYPROJECT["project"]["dependencies"] + PYPROJECT["project"]["optional-dependencies"]["test"]:
        req = Requirement(dep)
        name = req.name.lower().replace("_", "-")
        assert name in locked, f"constraints.txt has no pin for {req.name}"
        assert req.specifier.contains(locked[name]), f"constraints.txt pins {req.name} {locked[name]}, outside {dep}"


@pytest.mark.slow
def test_wheel_carries_every_module_and_model_file(tmp_path):
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(REPO)],
                   check=True, capture_output=True)
    (wheel,) = tmp_path.glob("bayes_roadload-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(REPO).as_posix() for p in (REPO / "bayes_roadload").rglob("*.py")}
    assert modules <= names, f"modules missing from the wheel: {sorted(modules - names)}"
    models = {f"bayes_roadload/models/{p.name}" for p in MODEL_FILES} | {"bayes_roadload/models/effects/library.toml"}
    assert models <= names, f"model files missing from the wheel: {sorted(models - names)}"
    assert f"-{bayes_roadload.__version__}-" in wheel.name
