"""Packaging: `pip install .` gives a working volec, its dependencies declared, its shipped
checkpoint and report viewer found as package data."""

from __future__ import annotations

import ast
import importlib.metadata
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]


def _declared() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return [Requirement(r) for r in project["dependencies"]]


def _locked() -> dict[str, str]:
    pins = {}
    for line in (ROOT / "environment.lock").read_text().splitlines():
        if "==" in line and not line.startswith("#"):
            name, version = line.split("==")
            pins[name.strip().lower().replace("_", "-")] = version.strip()
    return pins


def _third_party_imports() -> set[str]:
    stdlib = set(sys.stdlib_module_names)
    found = set()
    for path in (ROOT / "volec").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module] if isinstance(node, ast.ImportFrom) and node.module
                     and not node.level else [])
            found |= {n.split(".")[0] for n in names}
    return found - stdlib - {"volec", "__future__"}


def test_every_import_is_a_declared_dependency_pinned_in_the_lock():
    declared = {r.name.lower().replace("_", "-"): r for r in _declared()}
    providers = importlib.metadata.packages_distributions()
    for module in sorted(_third_party_imports()):
        dists = {d.lower().replace("_", "-") for d in providers.get(module, [])}
        assert dists & set(declared), f"volec imports {module} but pyproject.toml does not " \
            f"declare {sorted(dists) or 'its distribution'}"
    locked = _locked()
    for name, requirement in declared.items():
        assert name in locked, f"{name} is declared but not in environment.lock"
        assert requirement.specifier.contains(locked[name], prereleases=True), \
            f"environment.lock pins {name}=={locked[name]}, outside {requirement}"


def test_an_installed_volec_finds_its_checkpoint_outside_the_source_tree(tmp_path):
    source = tmp_path / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source / name)
    shutil.copytree(ROOT / "volec", source / "volec",
                    ignore=shutil.ignore_patterns("__pycache__"))
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps",
                    "--no-build-isolation", "--target", str(target), str(source)],
                   check=True, capture_output=True)
    shutil.rmtree(source)  # nothing may come from the source tree
    probe = ("import volec, volec.completion.complete as c, volec.estimate as e, volec.report as r;"
             "print(volec.__file__); print(c.SHIPPED_CHECKPOINT);"
             "print(e.load_completion_model(e.EstimateConfig()).cfg.n_input);"
             "print(len(r.viewer_script()))")
    env = {**os.environ, "PYTHONPATH": str(target)}
    out = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, env=env, check=True,
                         capture_output=True, text=True).stdout.splitlines()
    assert out[0].startswith(str(target)) and out[1].startswith(str(target))
    assert int(out[2]) > 0  # the network loaded from the installed checkpoint
    assert int(out[3]) > 100_000  # the report's bundled 3D viewer is package data too
    cli = subprocess.run([sys.executable, "-m", "volec", "--version"], cwd=tmp_path, env=env,
                         capture_output=True, text=True)
    assert cli.returncode == 0 and cli.stdout.startswith("volec ")
