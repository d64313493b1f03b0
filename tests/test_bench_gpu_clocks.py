"""GPU clocks during a benchmark, from `nvidia-smi`: the summary of its CSV rows, the sampler run against a stand-in
`nvidia-smi` (the lowest seam: the tool's output), and nothing at all where there is no such tool."""

import os
import stat
import textwrap

import pytest

from antarium.bench.gpu_clocks import FIELDS, GpuClocks, describe, summarise


def fake_nvidia_smi(folder, rows: list[str]) -> str:
    """An executable `nvidia-smi` that checks the query it is given and prints `rows` every 20 ms until stopped."""
    path = folder / "nvidia-smi"
    query = f"--query-gpu={','.join(FIELDS)}"
    body = "\n".join(f"  echo '{r}'" for r in rows)
    path.write_text(textwrap.dedent(f"""\
        #!/bin/sh
        [ "$1" = "{query}" ] && [ "$2" = "--format=csv,noheader,nounits" ] || {{ echo "bad query: $*" >&2; exit 2; }}
        while true; do
        {body}
          sleep 0.02
        done
        """))
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return str(path)


def test_rows_are_summarised_per_gpu_and_unreported_values_skipped():
    lines = ["0, 345, 1980, 80.42, 27", "0, 1680, 1980, 109.1, 37", "0, 1980, 1980, [N/A], 40",
             "1, 210, 1410, 60.0, 0", "", "index, clocks.sm", "garbage"]
    s = summarise(lines)
    assert set(s) == {"0", "1"}
    assert s["0"]["samples"] == 3 and s["0"]["sm_mhz"] == {"median": 1680.0, "min": 345.0, "max": 1980.0}
    assert s["0"]["sm_max_mhz"] == 1980.0 and s["0"]["power_w_median"] == pytest.approx(94.76)
    assert s["0"]["utilization_pct_median"] == 37.0
    assert describe(s)[0] == ("GPU 0: SM clock median 1,680 MHz (345-1,980 of 1,980), power 95 W, utilisation "
                              "37 % (3 samples, nvidia-smi)")
    assert summarise(["[N/A]"]) is None and describe(None) == []


def test_the_sampler_reads_the_tool_and_is_silent_without_it(tmp_path, monkeypatch):
    import time

    exe = fake_nvidia_smi(tmp_path, ["0, 345, 1980, 81.0, 27"])
    sampler = GpuClocks(exe).start()
    time.sleep(0.3)
    s = sampler.stop()
    assert s["0"]["samples"] >= 2 and s["0"]["sm_mhz"]["median"] == 345.0
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    assert GpuClocks().exe is None and GpuClocks().start().stop() is None


def test_bench_loop_writes_a_file_per_path_and_reports_the_clocks_on_the_gpu_path(tmp_path, capsys, monkeypatch):
    import json

    from antarium.cli import main

    tools = tmp_path / "bin"
    tools.mkdir()
    fake_nvidia_smi(tools, ["0, 1215, 1980, 109.0, 37"])
    monkeypatch.setenv("PATH", f"{tools}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.delenv("ANTARIUM_RIG_CONFIG", raising=False)
    out = tmp_path / "loop.json"
    assert main(["bench", "loop", "--seconds", "1", "--path", "cpu", "--path", "gpu", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert not out.exists()  # one file per path compared
    gpu = json.loads((tmp_path / "loop-gpu.json").read_text())
    cpu = json.loads((tmp_path / "loop-cpu.json").read_text())
    for path, result in (("cpu", cpu), ("gpu", gpu)):
        assert result["device"]["path"] == path and result["config"]["render"]["path"] == path
        assert result["frames"] > 0 and f"figures written to {tmp_path / f'loop-{path}.json'}" in text
    assert gpu["device"]["gpu_clocks"]["0"]["sm_mhz"]["median"] == 1215.0
    assert cpu["device"]["gpu_clocks"] is None  # the CPU path's frames do not wait for a GPU
    assert text.count("GPU 0: SM clock median 1,215 MHz") == 1


def test_the_sampler_reads_the_tool_as_it_writes_so_it_never_blocks_on_a_full_pipe(tmp_path, monkeypatch):
    import time

    # a stand-in 8-GPU nvidia-smi on PATH that writes 2,000 rounds (over 400 kB, far more than a pipe holds) as
    # fast as it can, then says it got that far and waits to be stopped
    done = tmp_path / "done"
    tools = tmp_path / "bin"
    tools.mkdir()
    exe = tools / "nvidia-smi"
    exe.write_text(textwrap.dedent(f"""\
        #!/bin/sh
        [ "$1" = "--query-gpu={','.join(FIELDS)}" ] || exit 2
        i=0
        while [ $i -lt 2000 ]; do
          for g in 0 1 2 3 4 5 6 7; do echo "$g, $((1000 + i)), 1980, 109.22, 27"; done
          i=$((i + 1))
        done
        touch {done}
        exec sleep 60
        """))
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("PATH", f"{tools}{os.pathsep}{os.environ['PATH']}")
    sampler = GpuClocks().start()
    deadline = time.monotonic() + 60  # the tool blocked on a full pipe never gets there (not a timing figure)
    while not done.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    s = sampler.stop()
    assert done.exists()
    assert all(s[str(g)]["samples"] == 2000 for g in range(8))
    assert s["0"]["sm_mhz"]["max"] == 2999.0
