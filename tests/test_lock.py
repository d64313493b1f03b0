"""The application's lock: every dependency pyproject.toml names is pinned in requirements.lock, within its range,
and the test environment runs the pinned versions (what `make demo` / `make test` install)."""

import re
import tomllib
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
PIN = re.compile(r"^([A-Za-z0-9_.\-]+)==([^\s;]+)\s*(?:;\s*(.+))?$")


def _pins() -> dict[str, list[tuple[str, str | None]]]:
    """canonical name -> [(version, environment marker or None)] from requirements.lock."""
    pins: dict[str, list[tuple[str, str | None]]] = {}
    for line in (ROOT / "requirements.lock").read_text().splitlines():
        m = PIN.match(line.strip())
        if m:
            pins.setdefault(canonicalize_name(m[1]), []).append((m[2], m[3]))
    return pins


def _requirements() -> list[Requirement]:
    """What `make test` installs: the dependencies, the test extra and the extras it names (`antarium[...]`)."""
    project = PYPROJECT["project"]
    extras = project["optional-dependencies"]
    out, todo = [], project["dependencies"] + extras["test"]
    while todo:
        req = Requirement(todo.pop(0))
        if canonicalize_name(req.name) == "antarium":
            todo += [r for extra in req.extras for r in extras[extra]]
        else:
            out.append(req)
    return out


@pytest.mark.parametrize("req", _requirements(), ids=str)
def test_every_dependency_is_pinned_within_its_range(req):
    pins = _pins().get(canonicalize_name(req.name))
    assert pins, f"{req.name} is in pyproject.toml but not in requirements.lock: run `make lock`"
    for pinned, _marker in pins:
        assert req.specifier.contains(pinned, prereleases=True), f"{req.name}=={pinned} is outside {req.specifier}"


def test_the_environment_runs_the_pinned_versions():
    from packaging.markers import Marker

    wrong = []
    for name, pins in _pins().items():
        wanted = [v for v, marker in pins if marker is None or Marker(marker).evaluate()]
        if not wanted:
            continue  # pinned for another platform or Python (e.g. colorama on Windows)
        try:
            have = version(name)
        except PackageNotFoundError:
            have = "missing"
        if have not in wanted:
            wrong.append(f"{name} {have} (locked {wanted[0]})")
    assert not wrong, "installed versions differ from requirements.lock: " + ", ".join(wrong)
