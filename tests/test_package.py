"""Packaging: the three folders import as subpackages of `antarium` from regular and editable installs;
`import antarium` stays light; every sub-command has --help."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from antarium.cli import COMMANDS, build_parser

ROOT = Path(__file__).resolve().parents[1]
SUBPACKAGES = ["antarium.geometry", "antarium.firmware_proto", "antarium.renderers"]


def _run_python(code: str, **kw) -> str:
    return subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, **kw).stdout


def test_editable_install_maps_the_folders():
    # the test environment is the editable install made by `make test`
    code = "import importlib; " + "; ".join(
        f"print(importlib.import_module({m!r}).__file__)" for m in SUBPACKAGES
    )
    files = _run_python(code).split()
    assert [Path(f).parent.name for f in files] == ["geometry", "firmware_proto", "renderers"]


def test_regular_install_imports_the_subpackages(tmp_path):
    # build from a copy, so that setuptools' build/ folder never lands in the checkout
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", ".git", "build", "*.egg-info", "__pycache__",
                                                             "demo-output", ".*_cache", ".hypothesis"))
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--target", str(target),
         str(src)],
        check=True, capture_output=True, text=True,
    )
    code = (
        f"import sys; sys.path.insert(0, {str(target)!r}); "
        + "import antarium, importlib; "
        + "; ".join(f"importlib.import_module({m!r})" for m in SUBPACKAGES)
        + "; from antarium.geometry import load_dome; d = load_dome(); "
        + "print(antarium.__file__); print(d.directions.shape)"
    )
    out = _run_python(code, cwd=tmp_path).split()
    assert out[0].startswith(str(target))
    assert out[1] == "(20350,"  # the shipped layout is package data


def test_import_antarium_pulls_in_no_gl_usb_or_zenoh():
    code = (
        "import sys, time; t = time.perf_counter(); import antarium, antarium.cli; "
        "dt = time.perf_counter() - t; "
        "print(dt); print(sorted(m for m in ('moderngl', 'usb', 'zenoh', 'h5py', 'matplotlib', 'scipy', "
        "'dask', 'distributed', 'pandas', 'pyarrow') "
        "if m in sys.modules))"
    )
    dt, loaded = _run_python(code).splitlines()
    assert loaded == "[]"
    assert float(dt) < 2.0  # generous: a cold import on a loaded CI machine


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_subcommand_has_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args([command, "--help"])
    assert exc.value.code == 0
    assert "usage: antarium " + command in capsys.readouterr().out


def test_version(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--version"])
    assert capsys.readouterr().out.startswith("antarium 0.")
