"""Movie writers fed one RGB frame at a time: animated GIF (Pillow) and MP4 (ffmpeg).

Neither keeps frames in memory: the GIF writer encodes each frame as it comes (one global palette
made from the first frame and the colour map, then only the rectangle that changed), the MP4
writer pipes raw frames to ffmpeg. Both write to a temporary name and rename when closed. The
ffmpeg is the one on PATH, else the static build the optional ``imageio-ffmpeg`` package ships
(``pip install 'flexmm[mp4]'``), so MP4 needs no system ffmpeg.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np

from flexmm.errors import OutputError, UsageError
from flexmm.io.atomic import temporary_name

MOVIE_SUFFIXES = (".gif", ".mp4")


#: colours every frame has: white, black, greys (text, edges, lines) and the status red
FIXED_COLOURS = np.array([[255, 255, 255], [0, 0, 0], *[[g, g, g] for g in range(17, 255, 17)], [192, 57, 43]],
                         np.uint8)


def make_palette(first: np.ndarray, extra: np.ndarray | None) -> np.ndarray:
    """(256, 3) palette: the fixed colours, extra colours (the colour map), then the first frame's
    most common other colours (median cut)."""
    from PIL import Image

    fixed = FIXED_COLOURS if extra is None else np.concatenate([FIXED_COLOURS, extra.reshape(-1, 3)])
    fixed = fixed[:200]
    rest = Image.fromarray(np.ascontiguousarray(first), "RGB").quantize(
        colors=256 - len(fixed), method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    more = np.asarray(rest.getpalette()[: 3 * (256 - len(fixed))], np.uint8).reshape(-1, 3)
    colours = np.concatenate([fixed, more])[:256]
    return np.concatenate([colours, np.zeros((256 - len(colours), 3), np.uint8)])


class Quantizer:
    """RGB frames to palette indices through a 6-bit-per-channel cube filled on demand (nearest
    palette colour to each cell's representative; exact at the cube's corners: white stays white)."""

    BITS = 6

    def __init__(self, palette: np.ndarray):
        self.palette = palette.astype(np.float32)
        n = 1 << self.BITS
        self.lut = np.full(n**3, -1, np.int16)
        self.levels = np.round(np.arange(n) * 255.0 / (n - 1)).astype(np.float32)

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        n = (1 << self.BITS) - 1
        q = (rgb.astype(np.int32) * n + 127) // 255
        cell = (q[..., 0] << (2 * self.BITS)) | (q[..., 1] << self.BITS) | q[..., 2]
        idx = self.lut[cell]
        missing = idx < 0
        if missing.any():
            new = np.unique(cell[missing])
            rep = np.stack([self.levels[new >> (2 * self.BITS)], self.levels[(new >> self.BITS) & n],
                            self.levels[new & n]], 1)
            for i in range(0, new.size, 8192):
                d = ((rep[i : i + 8192, None, :] - self.palette[None, :, :]) ** 2).sum(-1)
                self.lut[new[i : i + 8192]] = np.argmin(d, axis=1)
            idx = self.lut[cell]
        return idx.astype(np.uint8)


class GifWriter:
    """Animated GIF, encoded frame by frame (looping; frame duration 1/fps, in 10 ms steps)."""

    def __init__(self, path: Path, fps: float, extra_colours: np.ndarray | None = None):
        self.path, self.tmp = Path(path), temporary_name(path)
        self.duration_ms = max(20, round(100.0 / fps) * 10)
        self.extra = extra_colours
        self.fh = None
        self.palette = self.quantize = None
        self.previous = None
        self.n = 0

    def _header(self, width: int, height: int) -> bytes:
        return (b"GIF89a" + width.to_bytes(2, "little") + height.to_bytes(2, "little")
                + bytes([0xF7, 0, 0]) + self.palette.astype(np.uint8).tobytes()
                + b"!\xff\x0bNETSCAPE2.0\x03\x01\x00\x00\x00")  # loop forever

    def write(self, rgb: np.ndarray) -> None:
        """Encode one frame (the rectangle that changed since the previous one)."""
        from PIL import GifImagePlugin, Image

        if self.fh is None:
            self.palette = make_palette(rgb, self.extra)
            self.quantize = Quantizer(self.palette)
            self.fh = open(self.tmp, "wb")  # noqa: SIM115 - kept open across write() calls
            self.fh.write(self._header(rgb.shape[1], rgb.shape[0]))
        idx = self.quantize(rgb)
        if self.previous is None:
            box = (0, 0, idx.shape[1], idx.shape[0])
        else:
            changed = idx != self.previous
            rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
            box = (0, 0, 1, 1) if rows.size == 0 else (int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1)
        self.previous = idx
        part = Image.fromarray(np.ascontiguousarray(idx[box[1] : box[3], box[0] : box[2]]), "P")
        part.putpalette(self.palette.ravel().tolist())
        for chunk in GifImagePlugin.getdata(part, offset=box[:2], duration=self.duration_ms, disposal=1):
            self.fh.write(chunk)
        self.n += 1

    def close(self) -> Path:
        """Finish the file and move it into place."""
        if self.fh is None:
            raise OutputError(f"no frames to write to {self.path}")
        self.fh.write(b";")
        self.fh.close()
        os.replace(self.tmp, self.path)
        return self.path

    def abort(self) -> None:
        """Drop the partial file."""
        if self.fh is not None:
            self.fh.close()
        self.tmp.unlink(missing_ok=True)


def ffmpeg_or_error() -> str:
    """Path of an ffmpeg executable: the one on PATH, else imageio-ffmpeg's bundled static build;
    UsageError saying how to get one (or to write a GIF) when there is neither."""
    exe = shutil.which("ffmpeg")
    if exe is not None:
        return exe
    try:
        import imageio_ffmpeg
    except ImportError:
        pass
    else:
        try:
            return imageio_ffmpeg.get_ffmpeg_exe()
        except RuntimeError:  # its binary is missing for this platform
            pass
    raise UsageError("writing MP4 needs ffmpeg: install flexmm's mp4 extra, which brings a static ffmpeg "
                     "(pip install 'flexmm[mp4]'), or ffmpeg from your system's packages (e.g. apt install "
                     "ffmpeg, brew install ffmpeg), or write a GIF instead (--out movie.gif)")


class Mp4Writer:
    """H.264 MP4 through ffmpeg reading raw RGB frames on its standard input."""

    def __init__(self, path: Path, fps: float):
        self.path, self.tmp = Path(path), temporary_name(path)
        self.exe = ffmpeg_or_error()
        self.fps = fps
        self.proc = None
        self.n = 0

    def write(self, rgb: np.ndarray) -> None:
        """Send one frame to ffmpeg (started with the first frame's size)."""
        if self.proc is None:
            h, w = rgb.shape[:2]
            cmd = [self.exe, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
                   "-s", f"{w}x{h}", "-r", f"{self.fps:g}", "-i", "-", "-an", "-c:v", "libx264",
                   "-pix_fmt", "yuv420p", "-crf", "20", "-movflags", "+faststart", "-f", "mp4", str(self.tmp)]
            self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            self.proc.stdin.write(np.ascontiguousarray(rgb, np.uint8).tobytes())
        except BrokenPipeError:
            self._fail()
        self.n += 1

    def _fail(self):
        err = b""
        if self.proc is not None:
            self.proc.stdin.close()
            err = self.proc.stderr.read() or b""
            self.proc.wait()
        self.tmp.unlink(missing_ok=True)
        raise OutputError(f"ffmpeg failed writing {self.path}: {err.decode(errors='replace').strip()[-400:]}")

    def close(self) -> Path:
        """Wait for ffmpeg and move its file into place; OutputError if it failed."""
        if self.proc is None:
            raise OutputError(f"no frames to write to {self.path}")
        self.proc.stdin.close()
        err = self.proc.stderr.read() or b""
        if self.proc.wait() != 0 or not self.tmp.exists():
            self.tmp.unlink(missing_ok=True)
            raise OutputError(f"ffmpeg failed writing {self.path}: {err.decode(errors='replace').strip()[-400:]}")
        os.replace(self.tmp, self.path)
        return self.path

    def abort(self) -> None:
        """Stop ffmpeg and drop the partial file."""
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
        self.tmp.unlink(missing_ok=True)


def open_movie(path: Path, fps: float, extra_colours: np.ndarray | None = None):
    """The writer for ``path``'s suffix (.gif or .mp4)."""
    if path.suffix.lower() == ".mp4":
        return Mp4Writer(path, fps)
    return GifWriter(path, fps, extra_colours)


__all__ = ["MOVIE_SUFFIXES", "GifWriter", "Mp4Writer", "ffmpeg_or_error", "open_movie"]
