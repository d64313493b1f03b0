"""The virtual-ant examples run again into the same --out, as a lab reruns a protocol."""

import importlib.util
from pathlib import Path

import pytest

from antarium.trial_log import read_table

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _load(name):
    spec = importlib.util.spec_from_file_location(f"example_review_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name,stem", [("ant_homing", "homing"), ("ant_shuttle", "shuttle")])
def test_a_rerun_into_the_same_out_keeps_the_first_runs_log_and_reports_absolute_paths(name, stem, tmp_path,
                                                                                          monkeypatch, capsys):
    """The earlier run's log stays as it was; the new run writes <stem>-1.h5 and pictures named after it, and
    says where, absolute (a recording never overwrites a log: before, the rerun died with a LogError traceback)."""
    earlier = tmp_path / f"{stem}.h5"
    earlier.write_bytes(b"an earlier run's log")
    monkeypatch.chdir(tmp_path)
    assert _load(name).main(["--short", "--out", "."]) == 0
    assert earlier.read_bytes() == b"an earlier run's log"
    log = tmp_path / f"{stem}-1.h5"
    assert len(read_table(log, "frames")["x"]) > 0
    assert (tmp_path / f"{stem}-1_paths.png").stat().st_size > 10_000
    assert (tmp_path / f"{stem}-1_traces.png").stat().st_size > 10_000
    assert f"log {log}" in capsys.readouterr().out  # absolute, though --out was "."


@pytest.mark.parametrize("name", ["ant_homing", "ant_shuttle"])
def test_an_out_that_cannot_be_made_is_one_line(name, tmp_path, capsys):
    (tmp_path / "file").write_text("")
    module = _load(name)
    assert module.run_script(module.main, ["--short", "--out", str(tmp_path / "file" / "sub")]) == 2
    err = capsys.readouterr().err
    assert "error: --out: trial log folder" in err and "Traceback" not in err and not (tmp_path / "file").is_dir()
