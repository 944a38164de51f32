"""The package structure: lower packages never import higher ones, library modules never import CLI modules,
and the XLA flags are set in one place (no module imports ``jaxlp`` only for its side effect)."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = {"jaxlp": set(), "mjx_coman": {"jaxlp"}, "sweeps": {"jaxlp", "mjx_coman"}}
CLI_MODULES = {"mjx_coman.walk", "mjx_coman.seed000.cli", "mjx_coman.seed000.__main__", "mjx_coman.studies.cli",
               "mjx_coman.studies.__main__", "mjx_coman.experiments", "sweeps.cli", "sweeps.region_cli", "sweeps.engines_cli",
               "jaxlp.__main__", "sweeps.__main__"}
ENTRY_IMPORTERS = {"sweeps.cli", "sweeps.__main__"}  # the command line registers the subcommands
CLI_SUPPORT = "jaxlp.cliutil"  # what the command lines share; only they import it
CLI_USERS = {"sweeps.tune", "mjx_coman.mjcf"}  # library modules that also hold a command line's main


def _modules():
    for pkg in LAYERS:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
            yield pkg, name, ast.parse(path.read_text())


def _imports(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module
            for a in node.names:
                yield f"{node.module}.{a.name}"


@pytest.mark.parametrize("pkg, name, tree", list(_modules()), ids=lambda x: x if isinstance(x, str) else "")
def test_imports_go_down_the_layers_only(pkg, name, tree):
    for imp in _imports(tree):
        top = imp.split(".")[0]
        if top in LAYERS and top != pkg:
            assert top in LAYERS[pkg], f"{name} imports {imp}: {pkg} may import {sorted(LAYERS[pkg]) or 'nothing'}"
        if name not in ENTRY_IMPORTERS and name not in CLI_MODULES:
            assert imp not in CLI_MODULES, f"library module {name} imports the command-line module {imp}"
            assert not imp.startswith(CLI_SUPPORT) or name in CLI_USERS, f"library module {name} imports {imp}"


def test_no_module_imports_jaxlp_for_its_side_effect():
    for _, name, tree in _modules():
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                assert [a.name for a in node.names] != ["jaxlp"] or name.startswith("jaxlp"), name


def test_the_coman_mjcf_preset_comes_from_the_entry_point_not_an_import():
    from jaxlp import presets

    assert "coman-mjcf" in presets.robot_names()
    p = presets.get_params("coman-mjcf")
    assert 0.4 < float(p.h1) < 0.6  # COMAN's hip height
    with pytest.raises(ValueError, match="unknown robot 'nope'.*coman-mjcf"):
        presets.get_params("nope")
