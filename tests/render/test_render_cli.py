"""``flexmm render``: stills and movies, the run's status in the title, and bad options as messages.

Every user error exits with status 2 and one ``error: ...`` line, never a traceback.
"""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import LEGO_CHAIN
from PIL import Image
from render_helpers import build, random_fields, write_run
from typer.testing import CliRunner

from flexmm.cli import app
from flexmm.render.api import RenderOptions, still_figure

CHAIN = dict(LEGO_CHAIN, n_units=12, theta0_rad=0.1)
BISTABLE = {"kind": "mass_chain", "n_units": 10, "spacing_m": 0.01, "mass_kg": 0.01,
            "bond": {"law": "linear", "k_n_per_m": 100.0},
            "onsite": [{"law": "bistable_cubic", "alpha_n_per_m3": 5e6, "beta": 0.3, "jump_m": 0.01}]}
runner = CliRunner()


def invoke(*args):
    result = runner.invoke(app, ["render", *[str(a) for a in args]])
    assert "Traceback" not in result.output, result.output
    return result


@pytest.fixture
def chain_run(tmp_path) -> Path:
    _, system = build(CHAIN)
    write_run(tmp_path / "chain", CHAIN, system, random_fields(system, 6))
    return tmp_path / "chain"


def _texts(pic) -> str:
    return "\n".join(t.get_text() for t in pic.fig.fig.texts)


@pytest.mark.parametrize("status", ["interrupted", "failed"])
def test_unfinished_run_says_so_in_its_title(tmp_path, status):
    _, system = build(CHAIN)
    reason = f"{status} at t = 0.003 s; frames up to 0.003 s kept"
    run = write_run(tmp_path / "run", CHAIN, system, random_fields(system, 4),
                    attrs={"status": status, "status_reason": reason})
    text = _texts(still_figure(run, RenderOptions()))
    assert f"render_test — {status.upper()} RUN" in text
    assert reason.split(";")[0] in text
    result = invoke(run.parent, "-o", tmp_path / "last.png", "-q")
    assert result.exit_code == 0, result.output
    assert Image.open(tmp_path / "last.png").size[0] == 960


def test_finished_run_title_has_no_status(chain_run):
    text = _texts(still_figure(chain_run, RenderOptions()))
    assert "RUN" not in text.split("\n")[0] and "INTERRUPTED" not in text and "FAILED" not in text
    assert "t = 5 ms" in text  # the last frame (1 ms apart), time on the picture
    assert "drawn to scale" in text
    text = _texts(still_figure(chain_run, RenderOptions(exaggerate=10)))
    assert "×10 (exaggerated)" in text


@pytest.mark.parametrize("args, message", [
    (["--color", "bogus"], "error: --color 'bogus': no such field in the run; choose one of u, u_dot, theta"),
    (["--time", "1"], "error: --time 1 s is outside the run: its frames span 0 s to 0.005 s"),
    (["--time", "-1ms"], "error: --time -0.001 s is outside the run"),
    (["--time", "soon"], "error: --time 'soon': expected a time such as 0.25, 250ms or 40us"),
    (["--start", "2ms", "--stop", "1ms", "--out", "m.gif"], "error: --stop 0.001 s is before --start 0.002 s"),
    (["--out", "movie.avi"], ("error: --out movie.avi: unknown output suffix '.avi'; use .png or .svg for one "
                              "frame, .gif or .mp4 for a movie")),
    (["--out", "movie"], "unknown output suffix '(none)'"),
    (["--time", "1ms", "--out", "m.gif"], "error: --time picks one frame: write it as .png or .svg"),
    (["--start", "1ms", "--out", "f.png"], "error: --start, --stop and --every choose a movie's frames"),
    (["--clim", "1:0"], "error: --clim needs LOW < HIGH, got 1:0"),
    (["--clim", "a:b"], "error: --clim 'a:b': expected two numbers as LOW:HIGH"),
    (["--sites", "5:2"], "error: --sites '5:2': expected 0 ≤ A < B"),
    (["--sites", "100:200"], "error: --sites 100:200: no drawn unit in that range (columns 0 to 11)"),
    (["--exaggerate", "0"], "error: --exaggerate must be a positive number, got 0"),
    (["--fps", "0"], "error: --fps must be in (0, 100], got 0"),
    (["--every", "0"], "error: --every must be ≥ 1, got 0"),
    (["--shape", "triangle"], "error: --shape must be one of square, polygon, cross, bars, got 'triangle'"),
    (["--width", "10"], "error: --width must be between 320 and 4000 pixels, got 10"),
    (["--spacetime", "--row", "3"], "error: --row 3: the lattice has rows 0 to 0"),
    (["--spacetime", "--color", "none"], "error: --spacetime shows the colour quantity: choose one"),
    (["--color", "well"], "error: --color well: this lattice has no multistable elements"),
])
def test_bad_options_are_messages(chain_run, tmp_path, args, message):
    result = invoke(chain_run, "-o", tmp_path / "x.png", *args) if "--out" not in args else invoke(chain_run, *args)
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert not list(tmp_path.glob("x.png"))


def test_missing_run_is_a_message(tmp_path):
    result = invoke(tmp_path / "nowhere")
    assert result.exit_code == 2 and "error: no such run directory or file:" in result.output
    (tmp_path / "empty").mkdir()
    result = invoke(tmp_path / "empty")
    assert result.exit_code == 2 and "error: no dataset.nc in" in result.output


def test_mp4_without_ffmpeg_is_a_message(chain_run, tmp_path, monkeypatch):
    """Neither an ffmpeg on PATH nor the mp4 extra: a message saying how to get one, no file."""
    monkeypatch.setenv("PATH", str(tmp_path / "empty-bin"))
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # the extra not installed
    result = invoke(chain_run, "-o", tmp_path / "m.mp4")
    assert result.exit_code == 2
    assert "error: writing MP4 needs ffmpeg: install flexmm's mp4 extra" in result.output
    assert "pip install 'flexmm[mp4]'" in result.output and "--out movie.gif" in result.output
    assert not list(tmp_path.glob("m.mp4*"))


@pytest.mark.parametrize("args, message", [
    (["--out", "m.gif"], "error: --mp4 writes an MP4 movie: give --out NAME.mp4, not --out m.gif"),
    (["--time", "1ms"], "error: --mp4 writes a movie: --time picks one frame"),
])
def test_mp4_flag_conflicts_are_messages(chain_run, args, message):
    result = invoke(chain_run, "--mp4", *args)
    assert result.exit_code == 2, result.output
    assert message in result.output


def test_mp4_frames_are_piped_to_ffmpeg(chain_run, tmp_path, monkeypatch):
    """A stand-in ffmpeg records its arguments and the bytes it reads: one raw RGB image per frame."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "ffmpeg"
    fake.write_text(f"#!{sys.executable}\nimport json, sys\ndata = sys.stdin.buffer.read()\n"
                    "out = sys.argv[-1]\nopen(out, 'wb').write(b'mp4')\n"
                    f"json.dump({{'args': sys.argv[1:], 'bytes': len(data)}}, open({str(tmp_path / 'log.json')!r}, 'w'))\n")
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    result = invoke(chain_run, "-o", tmp_path / "m.mp4", "--fps", "25")
    assert result.exit_code == 0, result.output
    log = json.loads((tmp_path / "log.json").read_text())
    args = log["args"]
    w, h = map(int, args[args.index("-s") + 1].split("x"))
    assert w % 2 == 0 and h % 2 == 0 and args[args.index("-r") + 1] == "25"
    assert log["bytes"] == 6 * w * h * 3
    assert (tmp_path / "m.mp4").read_bytes() == b"mp4"


def test_mp4_without_system_ffmpeg(chain_run, tmp_path, monkeypatch):
    """``--mp4`` with no ffmpeg on PATH writes RUN/render.mp4 through the mp4 extra's static ffmpeg:
    an MP4 container ('ftyp' box first) holding the run's 6 frames at the picture's size."""
    ffmpeg = pytest.importorskip("imageio_ffmpeg", reason="the mp4 extra (imageio-ffmpeg) is not installed")
    monkeypatch.setenv("PATH", str(tmp_path / "empty-bin"))
    result = invoke(chain_run, "--mp4", "--fps", "10", "-q")
    assert result.exit_code == 0, result.output
    movie = chain_run / "render.mp4"
    assert result.output.strip() == str(movie)
    assert movie.read_bytes()[4:8] == b"ftyp"
    frames = ffmpeg.read_frames(str(movie))
    meta = next(frames)
    assert meta["codec"] == "h264" and meta["size"][0] == 960 and meta["fps"] == 10
    w, h = meta["size"]
    images = list(frames)
    assert len(images) == 6 and all(len(im) == w * h * 3 for im in images)
    assert not list(chain_run.glob("*.tmp*"))


def test_gif_movie_streams_every_frame(chain_run, tmp_path):
    result = invoke(chain_run, "-o", tmp_path / "m.gif", "--spacetime", "--fps", "10", "-q")
    assert result.exit_code == 0, result.output
    assert result.output.strip() == str(tmp_path / "m.gif")  # -q: only the path
    im = Image.open(tmp_path / "m.gif")
    assert im.n_frames == 6 and im.info["loop"] == 0 and im.info["duration"] == 100
    frames = []
    for k in range(im.n_frames):
        im.seek(k)
        frames.append(np.asarray(im.convert("RGB")))
    assert all(not np.array_equal(frames[k], frames[k + 1]) for k in range(5))
    assert tuple(frames[0][2, 2]) == (255, 255, 255)  # the palette keeps white white
    result = invoke(chain_run, "-o", tmp_path / "thin.gif", "--every", "2", "--start", "1ms", "-q")
    assert result.exit_code == 0 and Image.open(tmp_path / "thin.gif").n_frames == 3  # t = 1, 3, 5 ms
    result = invoke(chain_run, "-o", tmp_path / "few.gif", "--max-frames", "2", "-q")
    assert result.exit_code == 0 and Image.open(tmp_path / "few.gif").n_frames == 2


def test_svg_still_and_default_paths(chain_run):
    result = invoke(chain_run, "-t", "2ms", "-o", chain_run / "f.svg", "-q")
    assert result.exit_code == 0, result.output
    assert "<svg" in (chain_run / "f.svg").read_text()[:2000]
    assert invoke(chain_run, "-t", "2ms", "-q").output.strip() == str(chain_run / "render.png")
    assert invoke(chain_run, "-q").output.strip() == str(chain_run / "render.gif")


def test_predeformed_run_is_exaggerated_about_its_rest_state(tmp_path):
    """θ drawn = θ_rest + s (θ − θ_rest): the departure from the loaded state is what is magnified."""
    _, system = build(CHAIN)
    n = system.n_sites
    rest = {"u": np.linspace(0, -1e-3, n), "theta": np.full(n, 0.15)}
    fields = {"u": np.tile(rest["u"], (2, 1)), "theta": np.tile(rest["theta"], (2, 1))}
    fields["theta"][1, 5] += 0.01
    run = write_run(tmp_path / "run", CHAIN, system, fields, rest=rest)
    base = still_figure(run, RenderOptions(time_s=0.0, shape="square")).structure
    s = 7.0
    pic = still_figure(run, RenderOptions(time_s=1e-3, shape="square", exaggerate=s))
    centres, phi = pic.structure.state({"u": fields["u"][1], "theta": fields["theta"][1]})
    sigma = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    np.testing.assert_allclose(pic.structure.orientation(phi), sigma * (0.1 + 0.15 + s * (fields["theta"][1] - 0.15)), atol=1e-14)
    np.testing.assert_allclose(centres[:, 0], system.site_coords["x"] + rest["u"], atol=1e-15)
    assert base.scale == 1.0
    label = pic.colouring.label
    assert label.startswith("θ − θ_rest")


def test_saved_subset_of_sites(tmp_path):
    """output.site_stride > 1: the saved units are drawn, hinges only between saved neighbours."""
    _, system = build(CHAIN)
    run = write_run(tmp_path / "run", CHAIN, system, random_fields(system, 3), sites=np.arange(0, 12, 2))
    pic = still_figure(run, RenderOptions())
    assert len(pic.fig.polys.get_paths()) == 6
    assert "6 saved: output.site_stride > 1" in _texts(pic)
    result = invoke(run.parent, "-o", tmp_path / "e.png", "--color", "energy")
    assert result.exit_code == 2 and "--color energy needs every unit saved" in result.output


def test_wells_of_a_bistable_chain(tmp_path):
    """Sites past the barrier (βL from the first well) are coloured as the second well."""
    _, system = build(BISTABLE)
    u = np.zeros((2, 10))
    u[1, :4] = 0.0095  # switched to the well at L = 0.01
    u[1, 4] = 0.0025   # just below the barrier at 0.003
    run = write_run(tmp_path / "run", BISTABLE, system, {"u": u})
    pic = still_figure(run, RenderOptions())
    assert pic.colouring.name == "well" and pic.colouring.categories == ["well 1", "well 2"]
    np.testing.assert_array_equal(pic.fig.bodies.get_array(), [1, 1, 1, 1, 0, 0, 0, 0, 0, 0])


def test_frames_are_read_in_bounded_blocks(chain_run, monkeypatch):
    """A long run is streamed: each read covers at most BLOCK_BYTES of frames, and every frame
    yielded equals the stored one."""
    import h5py

    from flexmm.render import source

    monkeypatch.setattr(source, "BLOCK_BYTES", 2 * 12 * 8 * 2)  # two frames of two fields
    reads = []
    with source.RunSource(chain_run) as src:
        original = src.read

        def spy(names, i0, i1):
            reads.append(i1 - i0)
            return original(names, i0, i1)

        src.read = spy
        got = list(src.frames([0, 1, 2, 4, 5], ["u", "theta"]))
    assert max(reads) <= 2 and [g[0] for g in got] == [0, 1, 2, 4, 5]
    with h5py.File(chain_run / "dataset.nc") as f:
        for i, t, frame in got:
            np.testing.assert_array_equal(frame["theta"], f["theta"][i])
            assert t == f["time"][i]


def test_help_and_startup():
    result = runner.invoke(app, ["render", "--help"])
    assert result.exit_code == 0 and "<bool>" not in result.output and "BOOLEAN" not in result.output
    assert "--quiet" in result.output and "render" in runner.invoke(app, ["--help"]).output
    probe = ("import json, sys\nfrom typer.testing import CliRunner\nfrom flexmm.cli import app\n"
             "r = CliRunner().invoke(app, ['render', '--help'])\nassert r.exit_code == 0\n"
             "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
             "('matplotlib', 'xarray', 'numpy', 'PIL', 'h5netcdf'))))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300, check=False)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
