"""Ordinary mistakes get a message naming what is wrong, never a traceback (exit status 2).

Each case is a real ``flexmm`` process: a config that is not UTF-8, a YAML alias bomb, an output
directory that is a file, a data file given relative to the config, ``~`` in output paths, a
corrupted dataset given to analyze.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "lego_vector_soliton.yaml"
FLEXMM = str(Path(sys.executable).with_name("flexmm"))


def flexmm(*args, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([FLEXMM, *map(str, args)], capture_output=True, text=True, timeout=300, **kw)


def user_error(res: subprocess.CompletedProcess, *fragments: str) -> None:
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr and res.stderr.startswith("error:"), res.stderr
    for f in fragments:
        assert f in res.stderr, (f, res.stderr)


def test_config_that_is_not_utf8(tmp_path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"name: x\nlattice: {kind: \xff\xfe}\n")
    user_error(flexmm("validate", bad), f"{bad}:2:", "not UTF-8")


def test_yaml_alias_bomb_is_refused_at_once(tmp_path) -> None:
    lines = ['a: &a ["x","x","x","x","x","x","x","x","x"]']
    for prev, cur in zip("abcdefgh", "bcdefghi"):
        lines.append(f"{cur}: &{cur} [{', '.join([f'*{prev}'] * 9)}]")
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("\n".join(lines + ["name: x"]) + "\n")
    t0 = time.monotonic()
    user_error(flexmm("validate", bomb), "expands to", "aliases")
    assert time.monotonic() - t0 < 10


def test_output_directory_that_is_a_file_or_cannot_be_written(tmp_path) -> None:
    user_error(flexmm("validate", DEMO, "--set", "output.directory=/etc/passwd"), "/etc/passwd")
    user_error(flexmm("run", DEMO, "--set", "output.directory=/etc/passwd"), "/etc/passwd")
    for target in ("/proc/flexmm-x", "/sys/flexmm-x"):  # writable by permissions, not in fact
        user_error(flexmm("run", DEMO, "--out", target), "cannot create output directory")


def test_data_files_are_relative_to_the_config_and_home_is_expanded(tmp_path) -> None:
    data = yaml.safe_load((ROOT / "configs" / "e_tensegrity_rarefaction.yaml").read_text())
    (tmp_path / "cfg" / "tables").mkdir(parents=True)
    (tmp_path / "cfg" / "tables" / "law.csv").write_text(
        (ROOT / "configs" / "data" / "tensegrity_softening_force.csv").read_text())
    data["lattice"]["bond"]["csv"] = "tables/law.csv"
    data["solver"]["duration_s"] = data["solver"]["duration_s"] / 50
    data["output"] = {"directory": "~/x-should-be-expanded", "n_frames": 5}
    cfg = tmp_path / "cfg" / "scene.yaml"
    cfg.write_text(yaml.safe_dump(data))
    home = tmp_path / "home"
    home.mkdir()
    res = flexmm("run", cfg, "-q", env={"HOME": str(home), "PATH": "/usr/bin:/bin"}, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert Path(res.stdout.strip()) == home / "x-should-be-expanded" / data["name"] / "dataset.nc"
    assert not (tmp_path / "~").exists()


def test_corrupted_dataset_given_to_analyze(tmp_path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "dataset.nc").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 64)
    user_error(flexmm("analyze", run), "not a readable flexmm dataset")
    user_error(flexmm("analyze", tmp_path / "nothing-here"), "no such run directory")
